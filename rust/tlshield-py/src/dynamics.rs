//! The control-affine models of the shield and of the environments' plants: `Unicycle`,
//! `SingleIntegrator`, `DoubleIntegrator`, `AccelerationUnicycle`, `KinematicBicycle`. Each wraps a core
//! `Dynamics` and shares `eval`, `step` and `repr` (one `#[pymethods]` block per model from
//! `model_methods!`).

use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyTuple;
use tlshield_core::Dynamics;

use crate::convert::{indices, vector};
use crate::errors::map;
use crate::pickling::reduce;

/// `(f, g)` as numpy arrays.
pub(crate) type FG<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray2<f64>>);

/// `eval`, `step` and `__repr__` of a model class (its `inner` is the core model).
macro_rules! model_methods {
    ($ty:ty) => {
        #[pymethods]
        impl $ty {
            /// ``(f, g)`` at state ``s``: drift (n,) and input matrix (n, m).
            fn eval<'py>(&self, py: Python<'py>, s: &Bound<'py, PyAny>) -> PyResult<FG<'py>> {
                eval(py, &self.inner, s)
            }

            /// One Euler step ``s + dt (f(s) + g(s) a)``: the plant of an environment built on
            /// this model (Channel-v0 steps through it), the same code the shield's rows use.
            fn step<'py>(
                &self,
                py: Python<'py>,
                s: &Bound<'py, PyAny>,
                a: &Bound<'py, PyAny>,
                dt: f64,
            ) -> PyResult<Bound<'py, PyArray1<f64>>> {
                let next = self
                    .inner
                    .checked_euler_step(&vector(s, "s")?, &vector(a, "a")?, dt);
                Ok(map(next)?.into_pyarray(py))
            }

            fn __repr__(&self) -> String {
                self.inner.to_string()
            }

            /// Pickled as its constructor's arguments.
            fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
                let args = constructor_args(slf.py(), &slf.get().inner)?;
                reduce(slf.get_type().into_any(), args, None, None)
            }
        }
    };
}

/// The positional arguments of the model's constructor.
fn constructor_args<'py>(py: Python<'py>, model: &Dynamics) -> PyResult<Bound<'py, PyTuple>> {
    let items: Vec<Bound<'py, PyAny>> = match model {
        Dynamics::SingleIntegrator { pos } => vec![pos.clone().into_pyobject(py)?.into_any()],
        Dynamics::Unicycle { eps, x, y, theta } => vec![
            eps.into_pyobject(py)?.into_any(),
            x.into_pyobject(py)?.into_any(),
            y.into_pyobject(py)?.into_any(),
            theta.into_pyobject(py)?.into_any(),
        ],
        Dynamics::DoubleIntegrator { pos, vel } => vec![
            pos.clone().into_pyobject(py)?.into_any(),
            vel.clone().into_pyobject(py)?.into_any(),
        ],
        Dynamics::AccelerationUnicycle { x, y, theta, v } => vec![
            x.into_pyobject(py)?.into_any(),
            y.into_pyobject(py)?.into_any(),
            theta.into_pyobject(py)?.into_any(),
            v.into_pyobject(py)?.into_any(),
        ],
        Dynamics::KinematicBicycle { l, x, y, theta, v } => vec![
            l.into_pyobject(py)?.into_any(),
            x.into_pyobject(py)?.into_any(),
            y.into_pyobject(py)?.into_any(),
            theta.into_pyobject(py)?.into_any(),
            v.into_pyobject(py)?.into_any(),
        ],
        Dynamics::ThrustTurn {
            thrust,
            turn,
            drag,
            x,
            y,
            theta,
            vx,
            vy,
        } => {
            let mut items = vec![
                thrust.into_pyobject(py)?.into_any(),
                turn.into_pyobject(py)?.into_any(),
                drag.into_pyobject(py)?.into_any(),
            ];
            for d in [x, y, theta, vx, vy] {
                items.push(d.into_pyobject(py)?.into_any());
            }
            items
        }
    };
    PyTuple::new(py, items)
}

/// The Python model object of a core model (a shield's pickle names its model so).
pub fn to_python<'py>(py: Python<'py>, model: &Dynamics) -> PyResult<Bound<'py, PyAny>> {
    let inner = model.clone();
    Ok(match model {
        Dynamics::SingleIntegrator { .. } => {
            Bound::new(py, PySingleIntegrator { inner })?.into_any()
        }
        Dynamics::Unicycle { .. } => Bound::new(py, PyUnicycle { inner })?.into_any(),
        Dynamics::DoubleIntegrator { .. } => {
            Bound::new(py, PyDoubleIntegrator { inner })?.into_any()
        }
        Dynamics::AccelerationUnicycle { .. } => {
            Bound::new(py, PyAccelerationUnicycle { inner })?.into_any()
        }
        Dynamics::KinematicBicycle { .. } => {
            Bound::new(py, PyKinematicBicycle { inner })?.into_any()
        }
        Dynamics::ThrustTurn { .. } => Bound::new(py, PyThrustTurn { inner })?.into_any(),
    })
}

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
}
model_methods!(PyUnicycle);

/// ``ds[pos[i]]/dt = a[i]``: one input per listed state dimension.
#[pyclass(name = "SingleIntegrator", module = "tlshield._core", frozen)]
pub struct PySingleIntegrator {
    pub(crate) inner: Dynamics,
}

#[pymethods]
impl PySingleIntegrator {
    #[new]
    fn new(pos: &Bound<'_, PyAny>) -> PyResult<Self> {
        Ok(PySingleIntegrator {
            inner: map(Dynamics::single_integrator(indices(pos, "pos")?))?,
        })
    }
}
model_methods!(PySingleIntegrator);

/// ``ds[pos[i]]/dt = s[vel[i]]``, ``ds[vel[i]]/dt = a[i]``: one acceleration per position
/// dimension. Barriers on positions have relative degree 2 (the shield then needs ``alpha2``).
#[pyclass(name = "DoubleIntegrator", module = "tlshield._core", frozen)]
pub struct PyDoubleIntegrator {
    pub(crate) inner: Dynamics,
}

#[pymethods]
impl PyDoubleIntegrator {
    #[new]
    fn new(pos: &Bound<'_, PyAny>, vel: &Bound<'_, PyAny>) -> PyResult<Self> {
        Ok(PyDoubleIntegrator {
            inner: map(Dynamics::double_integrator(
                indices(pos, "pos")?,
                indices(vel, "vel")?,
            ))?,
        })
    }
}
model_methods!(PyDoubleIntegrator);

/// A unicycle driven by forward acceleration and turn rate: state ``x, y, theta, v`` at the
/// given dimensions, inputs ``(a, omega)``; ``dx = v cos theta``, ``dy = v sin theta``,
/// ``dtheta = omega``, ``dv = a``. Barriers on ``x, y`` have relative degree 2.
#[pyclass(name = "AccelerationUnicycle", module = "tlshield._core", frozen)]
pub struct PyAccelerationUnicycle {
    pub(crate) inner: Dynamics,
}

#[pymethods]
impl PyAccelerationUnicycle {
    #[new]
    #[pyo3(signature = (x=0, y=1, theta=2, v=3))]
    fn new(x: usize, y: usize, theta: usize, v: usize) -> PyResult<Self> {
        Ok(PyAccelerationUnicycle {
            inner: map(Dynamics::acceleration_unicycle(x, y, theta, v))?,
        })
    }
}
model_methods!(PyAccelerationUnicycle);

/// A kinematic bicycle about its rear axle with the given ``wheelbase``: state ``x, y, theta,
/// v`` at the given dimensions, inputs ``(a, tan delta)`` for steering angle ``delta``;
/// ``dx = v cos theta``, ``dy = v sin theta``, ``dtheta = v tan(delta) / wheelbase``,
/// ``dv = a``. The steering limit is the constant box ``|tan delta| <= tan(delta_max)`` on the
/// second input: the turn rate it allows shrinks with speed by the model itself. Barriers on
/// ``x, y`` have relative degree 2.
#[pyclass(name = "KinematicBicycle", module = "tlshield._core", frozen)]
pub struct PyKinematicBicycle {
    pub(crate) inner: Dynamics,
}

#[pymethods]
impl PyKinematicBicycle {
    #[new]
    #[pyo3(signature = (wheelbase, x=0, y=1, theta=2, v=3))]
    fn new(wheelbase: f64, x: usize, y: usize, theta: usize, v: usize) -> PyResult<Self> {
        Ok(PyKinematicBicycle {
            inner: map(Dynamics::kinematic_bicycle(wheelbase, x, y, theta, v))?,
        })
    }

    /// The wheelbase.
    #[getter]
    fn wheelbase(&self) -> f64 {
        match self.inner {
            Dynamics::KinematicBicycle { l, .. } => l,
            _ => unreachable!("a KinematicBicycle wraps the core bicycle"),
        }
    }
}
model_methods!(PyKinematicBicycle);

/// A body pushed along its heading, turned at a commanded rate and slowed by linear drag, its
/// velocity a state of its own: state ``x, y, theta, vx, vy`` at the given dimensions, inputs
/// ``(thrust, turn)``; ``dx = vx``, ``dy = vy``, ``dtheta = turn * a[1]``,
/// ``dvx = thrust * a[0] * cos(theta) - drag * vx`` (and ``sin`` for ``vy``).
/// Safety-Gymnasium's Point robot is this model (``tlshield.envs.safety_gym``). Barriers on
/// ``x, y`` have relative degree 2 and are acted on by the thrust alone; with
/// ``alpha <= drag <= alpha + alpha2`` the drag alone keeps them among still obstacles, so the
/// shield's QP has a solution at every heading.
#[pyclass(name = "ThrustTurn", module = "tlshield._core", frozen)]
pub struct PyThrustTurn {
    pub(crate) inner: Dynamics,
}

#[pymethods]
impl PyThrustTurn {
    #[new]
    #[pyo3(signature = (thrust, turn, drag, x=0, y=1, theta=2, vx=3, vy=4))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        thrust: f64,
        turn: f64,
        drag: f64,
        x: usize,
        y: usize,
        theta: usize,
        vx: usize,
        vy: usize,
    ) -> PyResult<Self> {
        Ok(PyThrustTurn {
            inner: map(Dynamics::thrust_turn(
                thrust,
                turn,
                drag,
                [x, y, theta, vx, vy],
            ))?,
        })
    }

    /// ``(thrust, turn, drag)``: acceleration per unit of the first input, turn rate per unit
    /// of the second, linear drag.
    #[getter]
    fn gains(&self) -> (f64, f64, f64) {
        match self.inner {
            Dynamics::ThrustTurn {
                thrust, turn, drag, ..
            } => (thrust, turn, drag),
            _ => unreachable!("a ThrustTurn wraps the core model"),
        }
    }
}
model_methods!(PyThrustTurn);

/// The core model of a Python model object; `None` for `None`.
pub fn model_of(obj: &Bound<'_, PyAny>) -> PyResult<Option<Dynamics>> {
    if obj.is_none() {
        return Ok(None);
    }
    if let Ok(d) = obj.cast::<PyUnicycle>() {
        return Ok(Some(d.get().inner.clone()));
    }
    if let Ok(d) = obj.cast::<PySingleIntegrator>() {
        return Ok(Some(d.get().inner.clone()));
    }
    if let Ok(d) = obj.cast::<PyDoubleIntegrator>() {
        return Ok(Some(d.get().inner.clone()));
    }
    if let Ok(d) = obj.cast::<PyAccelerationUnicycle>() {
        return Ok(Some(d.get().inner.clone()));
    }
    if let Ok(d) = obj.cast::<PyKinematicBicycle>() {
        return Ok(Some(d.get().inner.clone()));
    }
    if let Ok(d) = obj.cast::<PyThrustTurn>() {
        return Ok(Some(d.get().inner.clone()));
    }
    Err(PyTypeError::new_err(format!(
        "dynamics: expected tlshield.Unicycle, SingleIntegrator, DoubleIntegrator, \
         AccelerationUnicycle, KinematicBicycle, ThrustTurn, ControlAffine or None (then pass f and g to \
         every filter call), got {}",
        obj.get_type()
            .name()
            .map_or_else(|_| "?".into(), |n| n.to_string())
    )))
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
