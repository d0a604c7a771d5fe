//! Python bindings of tlshield: the compiled module `tlshield._core`.
//!
//! This crate only converts between Python/numpy and the core types and maps core errors to
//! Python exceptions; all logic lives in `tlshield-core`.

mod automaton;
mod barrier;
mod channel;
mod codes;
mod convert;
mod custom;
mod dynamics;
mod errors;
mod literals;
mod monitor;
mod pickling;
mod point_mass;
mod predicate;
mod progress;
mod shield;
mod shield_batch;
mod shield_filter;
mod shield_grad;
mod shield_pickle;
mod shield_results;
mod spec;
mod world;
mod world_infos;
mod world_step;

use pyo3::prelude::*;

/// Parses an scTLTL formula and returns its atoms in order of first appearance (raises
/// ``SpecError`` like ``Spec`` does). Useful to build predicates for a formula's atoms.
#[pyfunction]
fn formula_atoms(formula: &str) -> PyResult<Vec<String>> {
    let (_, atoms) = errors::map(tlshield_core::Formula::parse(formula))?;
    Ok(atoms)
}

/// The compiled core of tlshield. Import from `tlshield`, not from here.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("SpecError", m.py().get_type::<errors::SpecError>())?;
    m.add(
        "AutomatonError",
        m.py().get_type::<errors::AutomatonError>(),
    )?;
    m.add("ShieldError", m.py().get_type::<errors::ShieldError>())?;
    // The flag bits of `Shield.vjp_batch` (`tlshield.codes.GradFlag` reads them).
    m.add("GRAD_RELAXED", tlshield_core::shield::GRAD_RELAXED)?;
    m.add("GRAD_FAILED", tlshield_core::shield::GRAD_FAILED)?;
    m.add("GRAD_DEGENERATE", tlshield_core::shield::GRAD_DEGENERATE)?;
    m.add("GRAD_SINGULAR", tlshield_core::shield::GRAD_SINGULAR)?;
    m.add("GRAD_ROUTED", tlshield_core::shield::GRAD_ROUTED)?;
    // The outcome codes, name -> code (`tlshield.codes.Status` and `Solver` read them).
    let statuses = pyo3::types::PyDict::new(m.py());
    for s in tlshield_core::shield::Status::ALL {
        statuses.set_item(s.name(), s as u8)?;
    }
    m.add("STATUS_CODES", statuses)?;
    let solvers = pyo3::types::PyDict::new(m.py());
    for s in tlshield_core::shield::SolvedBy::ALL {
        solvers.set_item(s.name(), s as u8)?;
    }
    m.add("SOLVER_CODES", solvers)?;
    // The paper's task-reward defaults (Monitor, and the Python trackers read them).
    m.add("DEFAULT_C_R", tlshield_core::monitor::DEFAULT_C_R)?;
    m.add(
        "DEFAULT_TRAP_PENALTY",
        tlshield_core::monitor::DEFAULT_TRAP_PENALTY,
    )?;
    // The progress reward's defaults (Automaton.progress_reward and FsaAugmented read them).
    m.add("DEFAULT_GAMMA", tlshield_core::progress::DEFAULT_GAMMA)?;
    m.add("DEFAULT_HORIZON", tlshield_core::progress::DEFAULT_HORIZON)?;
    m.add(
        "DEFAULT_PROGRESS_SCALE",
        tlshield_core::progress::DEFAULT_SCALE,
    )?;
    m.add_class::<predicate::PyHalfspace>()?;
    m.add_class::<predicate::PyBall>()?;
    m.add_class::<predicate::PyUnion>()?;
    m.add_class::<predicate::PyIntersection>()?;
    m.add_class::<barrier::PyAvoid>()?;
    m.add_class::<barrier::PyInside>()?;
    m.add_class::<spec::PySpec>()?;
    m.add_class::<automaton::PyAutomaton>()?;
    m.add_class::<progress::PyProgressReward>()?;
    m.add_class::<monitor::PyMonitor>()?;
    m.add_class::<monitor::PyTaskStep>()?;
    m.add_class::<monitor::PyMonitorBatch>()?;
    m.add_class::<monitor::PyTaskBatch>()?;
    m.add_class::<dynamics::PyUnicycle>()?;
    m.add_class::<dynamics::PySingleIntegrator>()?;
    m.add_class::<dynamics::PyDoubleIntegrator>()?;
    m.add_class::<dynamics::PyAccelerationUnicycle>()?;
    m.add_class::<dynamics::PyKinematicBicycle>()?;
    m.add_class::<dynamics::PyThrustTurn>()?;
    m.add_class::<custom::PyControlAffine>()?;
    m.add_class::<shield::PyShield>()?;
    m.add_class::<shield::PyFilterResult>()?;
    m.add_class::<shield::PyFilterBatch>()?;
    m.add_class::<channel::PyChannelWorld>()?;
    m.add_class::<world_step::PyWorldStep>()?;
    m.add_class::<world::PyWorldsStep>()?;
    m.add_function(wrap_pyfunction!(world::step_worlds, m)?)?;
    m.add_class::<point_mass::PyPointMassWorld>()?;
    m.add_function(wrap_pyfunction!(formula_atoms, m)?)?;
    m.add_function(wrap_pyfunction!(pickling::_restore, m)?)?;
    Ok(())
}
