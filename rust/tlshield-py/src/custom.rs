//! `ControlAffine`: a user's own model `ds/dt = f(s) + g(s) a` given as Python callables. The
//! core keeps its structure (`tlshield_core::CustomModel`, probed here at construction); the
//! shield evaluates the callables at every state it is asked about and hands the values to the
//! core.

use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use tlshield_core::custom::{jacobian_by_differences, probe_states, PROBES};
use tlshield_core::CustomModel;

use crate::convert::{shape_text, vector, FloatArray};
use crate::dynamics::FG;
use crate::errors::{map, PyCoreError};
use crate::pickling::reduce;

/// A user's control-affine model ``ds/dt = f(s) + g(s) a``: ``f(s)`` returns the drift
/// ``(state_dim,)``, ``g(s)`` the input matrix ``(state_dim, inputs)``, and ``jacobian(s)``,
/// when given, the drift's Jacobian ``(state_dim, state_dim)`` (``[i, j] = df_i/ds_j``);
/// without it the Jacobian is computed by central differences of ``f`` (step
/// ``eps^(1/3) (1 + |s_j|)``, about 1e-10 accurate for smooth ``f``). Each callable gets a float64
/// array of the state and may return any array-like; a part that does not depend on the state
/// (a constant ``g``, the Jacobian of a linear ``f``) may be given as that array instead.
///
/// At construction the model is evaluated at ``probe`` states ``(k, state_dim)`` (default: 8
/// fixed states uniform in [-2, 2]) to find which dimensions the inputs move directly (rows of
/// ``g`` that are not zero) and which through one integration (``f`` reads a moved
/// dimension): from this, a shield gives every barrier its relative degree, with second-order
/// (HOCBF) rows where they are needed, as under a built-in model. Pass ``probe`` states where
/// the callables are defined if they are not defined everywhere.
#[pyclass(name = "ControlAffine", module = "tlshield._core", frozen)]
pub struct PyControlAffine {
    pub(crate) fns: Callables,
    probe: Option<Py<PyAny>>,
    pub(crate) inner: CustomModel,
}

/// One part of the model: a callable of the state, or a constant array (a `g` or a Jacobian
/// that does not depend on the state), kept as values and as a numpy copy for pickling.
enum Source {
    Call(Py<PyAny>),
    Fixed(Py<PyAny>, Vec<f64>),
}

impl Source {
    /// `obj` as a callable, or as a constant array of `shape`.
    fn new(obj: &Bound<'_, PyAny>, name: &str, shape: &[usize]) -> PyResult<Self> {
        if obj.is_callable() {
            return Ok(Source::Call(obj.clone().unbind()));
        }
        let layout = shape_text(shape);
        let array = FloatArray::extract(obj, name, shape.len(), &layout).map_err(|_| {
            PyTypeError::new_err(format!(
                "ControlAffine {name}: expected a callable s -> array or a constant array of \
                 shape {layout}, got {}",
                obj.get_type()
                    .name()
                    .map_or_else(|_| "?".into(), |n| n.to_string())
            ))
        })?;
        if array.shape() != shape {
            return Err(PyValueError::new_err(format!(
                "ControlAffine {name}: expected shape {layout}, got {}",
                shape_text(array.shape())
            )));
        }
        // Kept as a copy: a later change to the caller's array changes neither the model nor
        // its pickle.
        let values = array.values().to_vec();
        let copy = PyArray1::from_vec(obj.py(), values.clone()).reshape(shape.to_vec())?;
        Ok(Source::Fixed(copy.into_any().unbind(), values))
    }

    /// The object as given.
    fn given(&self, py: Python<'_>) -> Py<PyAny> {
        match self {
            Source::Call(obj) | Source::Fixed(obj, _) => obj.clone_ref(py),
        }
    }
}

/// The user's model over `n` state values and `m` inputs.
pub(crate) struct Callables {
    f: Source,
    g: Source,
    jacobian: Option<Source>,
    n: usize,
    m: usize,
}

impl Callables {
    /// Evaluates `source` at `s` and checks the answer's shape and values.
    fn call<'py>(
        &self,
        py: Python<'py>,
        source: &Source,
        name: &str,
        s: &[f64],
        shape: &[usize],
        out: &mut [f64],
    ) -> PyResult<()> {
        let fun = match source {
            Source::Fixed(_, values) => {
                out.copy_from_slice(values);
                return Ok(());
            }
            Source::Call(fun) => fun,
        };
        let layout = shape_text(shape);
        let answer = fun.call1(py, (s.to_vec().into_pyarray(py),))?;
        let array = FloatArray::extract(answer.bind(py), name, shape.len(), &layout)?;
        if array.shape() != shape {
            return Err(PyValueError::new_err(format!(
                "ControlAffine {name}(s): expected shape {layout}, got {}",
                shape_text(array.shape())
            )));
        }
        out.copy_from_slice(array.values());
        Ok(())
    }

    /// Writes `f(s)`, `g(s)` and, when `jac` is given, `J_f(s)` (given or by differences).
    pub(crate) fn evaluate(
        &self,
        py: Python<'_>,
        s: &[f64],
        f: &mut [f64],
        g: &mut [f64],
        jac: Option<&mut [f64]>,
    ) -> PyResult<()> {
        let (n, m) = (self.n, self.m);
        if s.len() != n {
            return Err(PyValueError::new_err(format!(
                "s: expected {n} values (the model's state_dim), got {}",
                s.len()
            )));
        }
        self.call(py, &self.f, "f", s, &[n], f)?;
        self.call(py, &self.g, "g", s, &[n, m], g)?;
        if let Some(jac) = jac {
            match &self.jacobian {
                Some(fun) => self.call(py, fun, "jacobian", s, &[n, n], jac)?,
                None => jacobian_by_differences(
                    s,
                    |x, out| self.call(py, &self.f, "f", x, &[n], out),
                    jac,
                )?,
            }
        }
        Ok(())
    }
}

impl PyControlAffine {
    /// Every row's `f`, `g` and `J_f` for `states` (rows x n), into flat buffers.
    pub(crate) fn evaluate_rows(
        &self,
        py: Python<'_>,
        states: &[f64],
    ) -> PyResult<(Vec<f64>, Vec<f64>, Vec<f64>)> {
        let (n, m) = (self.inner.state_len(), self.inner.inputs());
        let rows = states.len() / n.max(1);
        let alloc = |what: &str, per: usize| -> PyResult<Vec<f64>> {
            let len = map(tlshield_core::alloc::checked_len(what, &[rows, per]))?;
            let mut v = map(tlshield_core::alloc::try_with_capacity(what, len))?;
            v.resize(len, 0.0);
            Ok(v)
        };
        let (mut f, mut g, mut jac) = (
            alloc("f", n)?,
            alloc("g", n * m)?,
            alloc("jacobian", n * n)?,
        );
        for (i, s) in states.chunks_exact(n).enumerate() {
            self.fns.evaluate(
                py,
                s,
                &mut f[i * n..(i + 1) * n],
                &mut g[i * n * m..(i + 1) * n * m],
                Some(&mut jac[i * n * n..(i + 1) * n * n]),
            )?;
        }
        Ok((f, g, jac))
    }
}

#[pymethods]
impl PyControlAffine {
    #[new]
    #[pyo3(signature = (f, g, *, state_dim, inputs, jacobian=None, probe=None))]
    fn new(
        py: Python<'_>,
        f: &Bound<'_, PyAny>,
        g: &Bound<'_, PyAny>,
        state_dim: usize,
        inputs: usize,
        jacobian: Option<&Bound<'_, PyAny>>,
        probe: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        map(CustomModel::check_sizes(state_dim, inputs))?;
        let (n, m) = (state_dim, inputs);
        let fns = Callables {
            f: Source::new(f, "f", &[n])?,
            g: Source::new(g, "g", &[n, m])?,
            jacobian: jacobian
                .filter(|j| !j.is_none())
                .map(|j| Source::new(j, "jacobian", &[n, n]))
                .transpose()?,
            n,
            m,
        };
        let probe_obj = probe.filter(|p| !p.is_none());
        let states = match probe_obj {
            Some(p) => {
                let layout = format!("(k, {state_dim})");
                let array = FloatArray::extract(p, "probe", 2, &layout)?;
                if array.shape()[1] != state_dim || array.shape()[0] == 0 {
                    return Err(PyValueError::new_err(format!(
                        "probe: expected shape {layout} with k >= 1, got {}",
                        shape_text(array.shape())
                    )));
                }
                array.values().to_vec()
            }
            None => map(probe_states(state_dim, PROBES))?,
        };
        let inner = map(CustomModel::probe::<PyCoreError>(
            state_dim,
            inputs,
            &states,
            |s, f, g, jac| Ok(fns.evaluate(py, s, f, g, Some(jac))?),
        ))?;
        Ok(PyControlAffine {
            fns,
            probe: probe_obj.map(|p| p.clone().unbind()),
            inner,
        })
    }

    /// ``(f, g)`` at state ``s``: drift (n,) and input matrix (n, m).
    fn eval<'py>(&self, py: Python<'py>, s: &Bound<'py, PyAny>) -> PyResult<FG<'py>> {
        let s = vector(s, "s")?;
        let (n, m) = (self.inner.state_len(), self.inner.inputs());
        let (mut f, mut g) = (vec![0.0; n], vec![0.0; n * m]);
        self.fns.evaluate(py, &s, &mut f, &mut g, None)?;
        let g = numpy::ndarray::Array2::from_shape_vec((n, m), g)
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok((f.into_pyarray(py), g.into_pyarray(py)))
    }

    /// The drift's Jacobian at ``s`` (n, n), as the shield uses it: the given ``jacobian``,
    /// else central differences of ``f``.
    fn drift_jacobian<'py>(
        &self,
        py: Python<'py>,
        s: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let s = vector(s, "s")?;
        let (n, m) = (self.inner.state_len(), self.inner.inputs());
        let (mut f, mut g, mut jac) = (vec![0.0; n], vec![0.0; n * m], vec![0.0; n * n]);
        self.fns.evaluate(py, &s, &mut f, &mut g, Some(&mut jac))?;
        let jac = numpy::ndarray::Array2::from_shape_vec((n, n), jac)
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(jac.into_pyarray(py))
    }

    /// One Euler step ``s + dt (f(s) + g(s) a)``: the plant of an environment built on this
    /// model, the same callables the shield's rows use.
    fn step<'py>(
        &self,
        py: Python<'py>,
        s: &Bound<'py, PyAny>,
        a: &Bound<'py, PyAny>,
        dt: f64,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let (s, a) = (vector(s, "s")?, vector(a, "a")?);
        let (n, m) = (self.inner.state_len(), self.inner.inputs());
        let (mut f, mut g) = (vec![0.0; n], vec![0.0; n * m]);
        self.fns.evaluate(py, &s, &mut f, &mut g, None)?;
        let next = map(self.inner.checked_euler_step(&s, &a, dt, &f, &g))?;
        Ok(next.into_pyarray(py))
    }

    /// Number of state values.
    #[getter]
    fn state_dim(&self) -> usize {
        self.inner.state_len()
    }

    /// Number of inputs.
    #[getter]
    fn inputs(&self) -> usize {
        self.inner.inputs()
    }

    /// The state dimensions an input moves directly (rows of ``g`` not zero at a probe).
    #[getter]
    fn actuated(&self) -> Vec<usize> {
        self.inner.actuated()
    }

    /// The state dimensions an input moves through one integration (a barrier reading only
    /// these has relative degree 2).
    #[getter]
    fn integrated(&self) -> Vec<usize> {
        self.inner.integrated()
    }

    fn __repr__(&self) -> String {
        self.inner.to_string()
    }

    /// Pickled as its constructor's arguments; the callables as pickle stores functions (by
    /// their importable name: a lambda cannot be pickled).
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let me = slf.get();
        let kwargs = PyDict::new(py);
        kwargs.set_item("state_dim", me.inner.state_len())?;
        kwargs.set_item("inputs", me.inner.inputs())?;
        kwargs.set_item("jacobian", me.fns.jacobian.as_ref().map(|j| j.given(py)))?;
        kwargs.set_item("probe", me.probe.as_ref().map(|p| p.clone_ref(py)))?;
        let args = PyTuple::new(py, [me.fns.f.given(py), me.fns.g.given(py)])?;
        reduce(slf.get_type().into_any(), args, Some(kwargs), None)
    }
}
