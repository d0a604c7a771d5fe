//! Core errors -> Python exceptions. Every caller error is a `ValueError` (or subclass).

use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::PyErr;
use tlshield_core::{AutomatonError, InputError, ShieldError, SpecError as CoreSpecError};

create_exception!(
    tlshield,
    SpecError,
    PyValueError,
    "A formula that does not parse or is not scTLTL, or predicates that do not fit it."
);

/// Newtype so core errors can convert into `PyErr` (orphan rule).
pub struct PyCoreError(PyErr);

impl From<CoreSpecError> for PyCoreError {
    fn from(err: CoreSpecError) -> Self {
        PyCoreError(SpecError::new_err(err.to_string()))
    }
}

impl From<InputError> for PyCoreError {
    fn from(err: InputError) -> Self {
        PyCoreError(PyValueError::new_err(err.to_string()))
    }
}

impl From<AutomatonError> for PyCoreError {
    fn from(err: AutomatonError) -> Self {
        PyCoreError(PyValueError::new_err(err.to_string()))
    }
}

impl From<ShieldError> for PyCoreError {
    fn from(err: ShieldError) -> Self {
        PyCoreError(PyValueError::new_err(err.to_string()))
    }
}

impl From<PyCoreError> for PyErr {
    fn from(err: PyCoreError) -> Self {
        err.0
    }
}

/// Converts a core result into a `PyResult`.
pub fn map<T, E: Into<PyCoreError>>(result: Result<T, E>) -> Result<T, PyErr> {
    result.map_err(|e| e.into().into())
}
