//! `Avoid` and `Inside`: a user barrier's side, stated by its type (never by its name), and
//! the conversion of `Shield(barriers=...)` into core barriers.

use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyString, PyTuple};
use tlshield_core::{Barrier, Predicate};

use crate::predicate::{predicate_of, to_python};

/// The 0.3 spelling of "outside": a barrier name's first character (deprecated).
const OUTSIDE_PREFIX: char = '!';

/// Keep the state out of a predicate's region: the barrier `h = -rho(predicate)`
/// (`Shield(barriers={"shelf": Avoid(Ball(...))})`).
#[pyclass(name = "Avoid", module = "tlshield._core", frozen)]
pub struct PyAvoid {
    pub(crate) inner: Predicate,
}

/// Keep the state in a predicate's region: the barrier `h = rho(predicate)`
/// (`Shield(barriers={"arena": Inside(Halfspace(...))})`).
#[pyclass(name = "Inside", module = "tlshield._core", frozen)]
pub struct PyInside {
    pub(crate) inner: Predicate,
}

macro_rules! side_methods {
    ($ty:ident, $name:literal) => {
        #[pymethods]
        impl $ty {
            #[new]
            fn new(predicate: &Bound<'_, PyAny>) -> PyResult<Self> {
                Ok($ty {
                    inner: predicate_of(concat!($name, "(predicate)"), predicate)?,
                })
            }

            /// The predicate whose region the barrier is about.
            #[getter]
            fn predicate<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
                to_python(py, &self.inner)
            }

            fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
                Ok(format!(
                    "{}({})",
                    $name,
                    to_python(py, &self.inner)?.repr()?
                ))
            }

            fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
                other
                    .cast::<$ty>()
                    .is_ok_and(|o| o.get().inner == self.inner)
            }

            fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
                let py = slf.py();
                let args = PyTuple::new(py, [to_python(py, &slf.get().inner)?])?;
                crate::pickling::reduce(slf.get_type().into_any(), args, None, None)
            }
        }
    };
}

side_methods!(PyAvoid, "Avoid");
side_methods!(PyInside, "Inside");

/// The Python form of a core barrier: `Avoid(p)` or `Inside(p)`.
pub fn to_side<'py>(py: Python<'py>, b: &Barrier) -> PyResult<Bound<'py, PyAny>> {
    let inner = b.predicate.clone();
    Ok(match b.positive {
        true => Bound::new(py, PyInside { inner })?.into_any(),
        false => Bound::new(py, PyAvoid { inner })?.into_any(),
    })
}

fn fix(what: &str) -> String {
    format!(
        "{what}: a bare predicate does not say which side the state must keep; write \
         tlshield.Avoid(predicate) to keep the state out of its region, or \
         tlshield.Inside(predicate) to keep it in"
    )
}

/// One barrier from `value`: `Avoid(p)`, `Inside(p)`, or either with a slack weight
/// (`(Avoid(p), 1e-3)`). A bare predicate is refused, except under a name starting with `!`,
/// the 0.3 spelling of `Avoid`, which still means "outside" with a `DeprecationWarning`.
fn barrier(
    py: Python<'_>,
    what: &str,
    name: String,
    value: &Bound<'_, PyAny>,
) -> PyResult<Barrier> {
    let (value, weight) = match value.extract::<(Bound<'_, PyAny>, f64)>() {
        Ok((p, w)) => (p, w),
        Err(_) => (value.clone(), 1.0),
    };
    let bang = name.starts_with(OUTSIDE_PREFIX);
    let b = if let Ok(a) = value.cast::<PyAvoid>() {
        Barrier::outside(name, a.get().inner.clone())
    } else if let Ok(i) = value.cast::<PyInside>() {
        if bang {
            return Err(PyValueError::new_err(format!(
                "{what}: Inside(...) under a name starting with '!': the type keeps the state \
                 in, the name reads as 'outside'; use Avoid(...) or another name"
            )));
        }
        Barrier::inside(name, i.get().inner.clone())
    } else {
        let predicate =
            predicate_of(what, &value).map_err(|e| match e.is_instance_of::<PyTypeError>(py) {
                true => {
                    PyTypeError::new_err(format!(
                    "{what}: expected tlshield.Avoid(predicate) or tlshield.Inside(predicate), \
                     optionally with a slack weight, got {}",
                    value.get_type().name().map_or_else(|_| "?".into(), |n| n.to_string())
                ))
                }
                false => e,
            })?;
        if !bang {
            return Err(PyValueError::new_err(fix(what)));
        }
        PyErr::warn(
            py,
            &py.get_type::<pyo3::exceptions::PyDeprecationWarning>(),
            &std::ffi::CString::new(format!(
                "{what}: a name starting with '!' as the only sign of 'outside' is deprecated \
                 (removed in 0.5: then an error); write tlshield.Avoid(predicate)"
            ))?,
            2,
        )?;
        Barrier::outside(name, predicate)
    };
    Ok(b.with_slack_weight(weight))
}

/// Barriers from a mapping name -> `Avoid(p)` / `Inside(p)` (or `(side, slack weight)`), or a
/// sequence of them (named `h0`, `h1`, ...).
pub fn barriers(obj: &Bound<'_, PyAny>) -> PyResult<Vec<Barrier>> {
    let py = obj.py();
    if let Ok(items) = obj.call_method0("items") {
        let mut out = Vec::new();
        for item in items.try_iter()? {
            let (key, value): (Bound<'_, PyAny>, Bound<'_, PyAny>) = item?.extract()?;
            if !key.is_instance_of::<PyString>() {
                return Err(PyTypeError::new_err(
                    "barriers: mapping keys must be names (str)",
                ));
            }
            let name: String = key.extract()?;
            out.push(barrier(py, &format!("barriers[{name:?}]"), name, &value)?);
        }
        return Ok(out);
    }
    let iter = obj.try_iter().map_err(|_| {
        PyTypeError::new_err(
            "barriers: expected a mapping name -> Avoid(...)/Inside(...) or a sequence of them",
        )
    })?;
    let mut out = Vec::new();
    for (i, item) in iter.enumerate() {
        let name = Barrier::default_name(i);
        out.push(barrier(py, &format!("barriers[{i}]"), name, &item?)?);
    }
    Ok(out)
}
