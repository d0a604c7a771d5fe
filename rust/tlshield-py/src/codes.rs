//! The shield's outcome codes as the Python enums `tlshield.codes.Status` and `Solver`
//! (`IntEnum`s, one encoding for `filter` and `filter_batch`). The classes are looked up once.

use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::PyType;

static STATUS: PyOnceLock<Py<PyType>> = PyOnceLock::new();
static SOLVER: PyOnceLock<Py<PyType>> = PyOnceLock::new();

fn member<'py>(
    py: Python<'py>,
    cell: &'static PyOnceLock<Py<PyType>>,
    name: &str,
    code: u8,
) -> PyResult<Bound<'py, PyAny>> {
    cell.import(py, "tlshield.codes", name)?.call1((code,))
}

/// `tlshield.codes.Status(code)`.
pub fn status(py: Python<'_>, code: u8) -> PyResult<Bound<'_, PyAny>> {
    member(py, &STATUS, "Status", code)
}

/// `tlshield.codes.Solver(code)`.
pub fn solver(py: Python<'_>, code: u8) -> PyResult<Bound<'_, PyAny>> {
    member(py, &SOLVER, "Solver", code)
}
