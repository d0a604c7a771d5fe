//! `Unicycle` and `SingleIntegrator`: the control-affine models of the shield and of the
//! environments' plants.

use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use tlshield_core::Dynamics;

use crate::convert::vector;
use crate::errors::map;

/// `(f, g)` as numpy arrays.
type FG<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray2<f64>>);

/// The unicycle's reference point ``eps`` ahead of its centre (paper Eq. 6A2): inputs
/// ``(a_v, a_theta)``; ``x``, ``y``, ``theta`` are the state dimensions of the reference
/// point and the heading.
#[pyclass(name = "Unicycle", module = "tlshield._core", frozen)]
pub struct PyUnicycle {
    pub(crate) inner: Dynamics,
}

#[pymethods]
impl PyUnicycle {
    #[new]
    #[pyo3(signature = (eps, x=0, y=1, theta=2))]
    fn new(eps: f64, x: usize, y: usize, theta: usize) -> PyResult<Self> {
        Ok(PyUnicycle {
            inner: map(Dynamics::unicycle(eps, x, y, theta))?,
        })
    }

    /// ``(f, g)`` at state ``s``: drift (n,) and input matrix (n, m).
    fn eval<'py>(&self, py: Python<'py>, s: &Bound<'py, PyAny>) -> PyResult<FG<'py>> {
        eval(py, &self.inner, s)
    }

    /// One Euler step ``s + dt (f(s) + g(s) a)``: the plant of an environment built on this
    /// model (Channel-v0 steps through it), the same code the shield's constraints use.
    fn step<'py>(
        &self,
        py: Python<'py>,
        s: &Bound<'py, PyAny>,
        a: &Bound<'py, PyAny>,
        dt: f64,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        step(py, &self.inner, s, a, dt)
    }

    fn __repr__(&self) -> String {
        match &self.inner {
            Dynamics::Unicycle { eps, x, y, theta } => {
                format!("Unicycle(eps={eps}, x={x}, y={y}, theta={theta})")
            }
            Dynamics::SingleIntegrator { .. } => unreachable!("PyUnicycle wraps a unicycle"),
        }
    }
}

/// ``ds[pos[i]]/dt = a[i]``: one input per listed state dimension.
#[pyclass(name = "SingleIntegrator", module = "tlshield._core", frozen)]
pub struct PySingleIntegrator {
    pub(crate) inner: Dynamics,
}

#[pymethods]
impl PySingleIntegrator {
    #[new]
    fn new(pos: &Bound<'_, PyAny>) -> PyResult<Self> {
        let pos = crate::convert::indices(pos, "pos")?;
        Ok(PySingleIntegrator {
            inner: map(Dynamics::single_integrator(pos))?,
        })
    }

    /// ``(f, g)`` at state ``s``: drift (n,) and input matrix (n, m).
    fn eval<'py>(&self, py: Python<'py>, s: &Bound<'py, PyAny>) -> PyResult<FG<'py>> {
        eval(py, &self.inner, s)
    }

    /// One Euler step ``s + dt (f(s) + g(s) a)``: the plant of an environment built on this
    /// model (Channel-v0 steps through it), the same code the shield's constraints use.
    fn step<'py>(
        &self,
        py: Python<'py>,
        s: &Bound<'py, PyAny>,
        a: &Bound<'py, PyAny>,
        dt: f64,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        step(py, &self.inner, s, a, dt)
    }

    fn __repr__(&self) -> String {
        match &self.inner {
            Dynamics::SingleIntegrator { pos } => format!("SingleIntegrator(pos={pos:?})"),
            Dynamics::Unicycle { .. } => unreachable!("PySingleIntegrator wraps an integrator"),
        }
    }
}

fn eval<'py>(py: Python<'py>, dynamics: &Dynamics, s: &Bound<'py, PyAny>) -> PyResult<FG<'py>> {
    let s = vector(s, "s")?;
    map(dynamics.check_state(&s))?;
    let (n, m) = (s.len(), dynamics.inputs());
    let (mut f, mut g) = (vec![0.0; n], vec![0.0; n * m]);
    dynamics.eval(&s, &mut f, &mut g);
    let g = numpy::ndarray::Array2::from_shape_vec((n, m), g)
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok((f.into_pyarray(py), g.into_pyarray(py)))
}

fn step<'py>(
    py: Python<'py>,
    dynamics: &Dynamics,
    s: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    dt: f64,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let next = dynamics.checked_euler_step(&vector(s, "s")?, &vector(a, "a")?, dt);
    Ok(map(next)?.into_pyarray(py))
}
