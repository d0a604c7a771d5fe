//! Copy and pickle as data. Every class reduces to ``_restore(version, make, args, kwargs)``:
//! the constructor (or the method) that rebuilds it, with its arguments as numbers, strings,
//! lists, the formula text and other tlshield objects, never code. Objects that change as they
//! run (monitors, worlds) add a state of the same kind, which their ``__setstate__`` checks.
//! ``_restore`` refuses a pickle written by another tlshield version: its layout may differ.

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

/// The version written into every pickle, and the only one `_restore` loads.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// Rebuilds a pickled tlshield object: ``make(*args, **kwargs)`` after checking that the
/// pickle was written by this version of tlshield (``ValueError`` otherwise).
#[pyfunction]
#[pyo3(signature = (version, make, args, kwargs=None))]
pub fn _restore<'py>(
    version: &Bound<'py, PyAny>,
    make: &Bound<'py, PyAny>,
    args: &Bound<'py, PyTuple>,
    kwargs: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let written = version
        .extract::<String>()
        .unwrap_or_else(|_| format!("{version:?}"));
    if written != VERSION {
        return Err(PyValueError::new_err(format!(
            "this pickle of a tlshield object was written by tlshield {written}; this is \
             tlshield {VERSION}, which loads only its own (rebuild the object, or load the \
             pickle with tlshield {written})"
        )));
    }
    make.call(args, kwargs)
}

/// What ``__reduce__`` returns: ``(_restore, (version, make, args, kwargs))``, and ``state``
/// third when the object has one (pickle hands it to ``__setstate__``).
pub fn reduce<'py>(
    make: Bound<'py, PyAny>,
    args: Bound<'py, PyTuple>,
    kwargs: Option<Bound<'py, PyDict>>,
    state: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let py = make.py();
    let restore = py.import("tlshield._core")?.getattr("_restore")?;
    let kwargs = match kwargs {
        Some(k) => k.into_any(),
        None => PyDict::new(py).into_any(),
    };
    let call = PyTuple::new(
        py,
        [
            VERSION.into_pyobject(py)?.into_any(),
            make,
            args.into_any(),
            kwargs,
        ],
    )?;
    match state {
        Some(state) => PyTuple::new(py, [restore, call.into_any(), state]),
        None => PyTuple::new(py, [restore, call.into_any()]),
    }
}
