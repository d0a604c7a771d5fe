//! Core errors -> Python exceptions. Every caller error is a `ValueError`: `SpecError`,
//! `AutomatonError` and `ShieldError` for their concerns (every input problem of a shield's
//! call is a `ShieldError`), plain `ValueError` for bad numeric input outside them; a size
//! that cannot be allocated is a `MemoryError`.

use pyo3::create_exception;
use pyo3::exceptions::{PyMemoryError, PyValueError};
use pyo3::types::PyAnyMethods;
use pyo3::{PyErr, PyResult};
use tlshield_core::{
    AutomatonError as CoreAutomatonError, InputError, ShieldError as CoreShieldError,
    SpecError as CoreSpecError,
};

create_exception!(
    tlshield,
    SpecError,
    PyValueError,
    "A formula that does not parse or is not scTLTL, or predicates that do not fit it."
);

create_exception!(
    tlshield,
    AutomatonError,
    PyValueError,
    "A problem building or using an automaton (too many atoms, an unknown state, a reward asked \
     of the trap)."
);

create_exception!(
    tlshield,
    ShieldError,
    PyValueError,
    "A problem configuring or calling a shield (a bad parameter, a state or action that does not \
     fit it)."
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
        match err {
            // A size that cannot be allocated is Python's MemoryError, as numpy raises it.
            InputError::TooLarge { .. } => PyCoreError(PyMemoryError::new_err(err.to_string())),
            other => PyCoreError(PyValueError::new_err(other.to_string())),
        }
    }
}

impl From<CoreAutomatonError> for PyCoreError {
    fn from(err: CoreAutomatonError) -> Self {
        match err {
            CoreAutomatonError::Input(input) => input.into(),
            other => PyCoreError(AutomatonError::new_err(other.to_string())),
        }
    }
}

impl From<CoreShieldError> for PyCoreError {
    fn from(err: CoreShieldError) -> Self {
        // Every input problem of a shield call is a ShieldError (a ValueError), as its
        // docstring promises, but for a size past memory (MemoryError).
        let input = |i: InputError| match i {
            InputError::TooLarge { .. } => i.into(),
            other => PyCoreError(ShieldError::new_err(other.to_string())),
        };
        match err {
            CoreShieldError::Input(i)
            | CoreShieldError::Automaton(CoreAutomatonError::Input(i)) => input(i),
            // A monitor read before its episode starts is one error wherever it is read (the
            // monitor's, a batch's or a shield's call): AutomatonError.
            CoreShieldError::Automaton(aut @ CoreAutomatonError::NotReset { .. }) => aut.into(),
            // A q the automaton does not have: the call's input too.
            other => PyCoreError(ShieldError::new_err(other.to_string())),
        }
    }
}

impl From<PyErr> for PyCoreError {
    fn from(err: PyErr) -> Self {
        PyCoreError(err)
    }
}

impl From<PyCoreError> for PyErr {
    fn from(err: PyCoreError) -> Self {
        err.0
    }
}

/// Runs a shield call's body, raising every input problem it finds as a `ShieldError`: those
/// the core reports already are; a plain `ValueError` found while converting the arguments (a
/// shape, a length) is re-raised as one with the same message. `TypeError`, `MemoryError` and
/// `AutomatonError` (a monitor without an episode) stay as they are.
pub fn shield_call<T>(py: pyo3::Python<'_>, body: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    body().map_err(
        |err| match err.get_type(py).is(py.get_type::<PyValueError>()) {
            true => ShieldError::new_err(err.value(py).to_string()),
            false => err,
        },
    )
}

/// An FSA state the automaton does not have, found while converting a shield call's `q`: the
/// call's input, so a `ShieldError` (the automaton's own calls raise `AutomatonError`).
pub fn shield_state(py: pyo3::Python<'_>, err: PyErr) -> PyErr {
    match err.is_instance_of::<AutomatonError>(py) {
        true => ShieldError::new_err(err.value(py).to_string()),
        false => err,
    }
}

/// Converts a core result into a `PyResult`.
pub fn map<T, E: Into<PyCoreError>>(result: Result<T, E>) -> Result<T, PyErr> {
    result.map_err(|e| e.into().into())
}
