//! `WorldStep`: what one step of a bundled world (`ChannelWorld.step`, `PointMassWorld.step`)
//! gives, converted from the core's.

use numpy::{IntoPyArray, PyArray1};
use pyo3::prelude::*;
use tlshield_core::world::WorldStep;

use crate::shield::{PyFilterResult, PyShield};

/// What one step of a bundled world gives (``ChannelWorld.step``, ``PointMassWorld.step``).
#[pyclass(name = "WorldStep", module = "tlshield._core", frozen, get_all)]
pub struct PyWorldStep {
    /// The observation at the new state, one-hot FSA state included.
    observation: Py<PyArray1<f64>>,
    /// The RL action in physical units (2,).
    a_rl: Py<PyArray1<f64>>,
    /// The action applied to the plant (2,).
    action: Py<PyArray1<f64>>,
    /// The shield's answer, or None without a shield.
    shield: Option<Py<PyFilterResult>>,
    /// The FSA state after the step.
    q: usize,
    /// The task reward of the step.
    tl_reward: f64,
    /// The task is done.
    accepted: bool,
    /// The task can no longer be done.
    trapped: bool,
    /// The environment's reward.
    reward: f64,
    /// The episode ended.
    terminated: bool,
    /// The horizon was reached.
    truncated: bool,
    /// The world's two constraints at the new state (Channel-v0: c1, c2; PointMass-v0: the
    /// obstacles' clearances).
    constraints: (f64, f64),
    /// Distance to the nearer obstacle (Channel-v0: its centre; PointMass-v0: its edge).
    min_obstacle_distance: f64,
    /// In collision.
    collision: bool,
    /// A constraint of the task is violated.
    violation: bool,
}

impl PyWorldStep {
    /// Converts a core step and its observation (the shield's answer through `shield`).
    pub fn new(
        py: Python<'_>,
        step: WorldStep,
        observation: Vec<f64>,
        shield: Option<PyRef<'_, PyShield>>,
    ) -> PyResult<Self> {
        let m = step.measure;
        Ok(PyWorldStep {
            observation: observation.into_pyarray(py).unbind(),
            a_rl: step.a_rl.to_vec().into_pyarray(py).unbind(),
            action: step.applied.to_vec().into_pyarray(py).unbind(),
            shield: match (shield, step.shield.and_then(|s| s.record)) {
                (Some(sh), Some(f)) => Some(Py::new(py, sh.result(py, f))?),
                _ => None,
            },
            q: step.task.q,
            tl_reward: step.task.reward,
            accepted: step.task.accepted,
            trapped: step.task.trapped,
            reward: step.reward,
            terminated: step.terminated,
            truncated: step.truncated,
            constraints: (m.h[0], m.h[1]),
            min_obstacle_distance: m.min_obstacle_distance,
            collision: m.collision,
            violation: m.violation,
        })
    }
}
