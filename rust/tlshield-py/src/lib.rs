//! Python bindings of tlshield: the compiled module `tlshield._core`.
//!
//! This crate only converts between Python/numpy and the core types and maps core errors to
//! Python exceptions; all logic lives in `tlshield-core`.

mod convert;
mod errors;
mod predicate;
mod spec;

use pyo3::prelude::*;

/// The compiled core of tlshield. Import from `tlshield`, not from here.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("SpecError", m.py().get_type::<errors::SpecError>())?;
    m.add_class::<predicate::PyHalfspace>()?;
    m.add_class::<predicate::PyBall>()?;
    m.add_class::<spec::PySpec>()?;
    Ok(())
}
