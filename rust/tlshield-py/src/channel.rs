//! `ChannelWorld`: the case study's world stepped in the core (core `channel`), and
//! `ChannelStep`, what one step gives.

use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use tlshield_core::channel::{ChannelParams, ChannelStep, ChannelWorld, Obstacle, STATE_DIM};

use crate::convert::FloatArray;
use crate::dynamics::PyUnicycle;
use crate::errors::map;
use crate::monitor::PyMonitor;
use crate::shield::{PyFilterResult, PyShield};

/// The paper's case study (Sec. VI) stepped in the core: the plant (through ``model``, the
/// shield's model), the obstacles, the shield call, the task monitor, the reward terms and the
/// observation, in one call per step. ``tlshield/Channel-v0`` is a Gymnasium shell around it
/// (it draws the episodes and builds ``info``).
#[pyclass(name = "ChannelWorld", module = "tlshield._core")]
pub struct PyChannelWorld {
    inner: ChannelWorld,
}

fn pair(values: Vec<f64>, name: &str) -> PyResult<[f64; 2]> {
    <[f64; 2]>::try_from(values)
        .map_err(|v| PyValueError::new_err(format!("{name}: expected 2 values, got {}", v.len())))
}

impl PyChannelWorld {
    /// The observation at the current state, then the monitor's one-hot FSA state.
    fn observation(&self, monitor: &tlshield_core::Monitor) -> Vec<f64> {
        let n = monitor.automaton().num_states();
        let mut obs = vec![0.0; self.inner.observation_len(n)];
        self.inner.observe(monitor, n, &mut obs);
        obs
    }
}

#[pymethods]
impl PyChannelWorld {
    #[new]
    #[pyo3(signature = (
        model, *, dt, horizon, arena, half_width, obstacle_radius, safe_distance, w,
        collision_penalty, intervention_penalty, relative, rl_bounds, obstacle_drift,
        evaluation, channel_atoms,
    ))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        model: PyRef<'_, PyUnicycle>,
        dt: f64,
        horizon: u32,
        arena: (f64, f64),
        half_width: f64,
        obstacle_radius: f64,
        safe_distance: f64,
        w: f64,
        collision_penalty: f64,
        intervention_penalty: f64,
        relative: bool,
        rl_bounds: (Vec<f64>, Vec<f64>),
        obstacle_drift: bool,
        evaluation: bool,
        channel_atoms: (usize, usize),
    ) -> PyResult<Self> {
        let params = ChannelParams {
            dt,
            horizon,
            arena,
            half_width,
            obstacle_radius,
            safe_distance,
            w,
            collision_penalty,
            intervention_penalty,
            relative,
            rl_bounds: (
                pair(rl_bounds.0, "rl_bounds[0]")?,
                pair(rl_bounds.1, "rl_bounds[1]")?,
            ),
            obstacle_drift,
            evaluation,
            channel_atoms: [channel_atoms.0, channel_atoms.1],
        };
        Ok(PyChannelWorld {
            inner: ChannelWorld::new(params, model.inner.clone()),
        })
    }

    /// Starts an episode at ``s0`` (13,) with the obstacle paths ``obstacles`` (2, 4): per
    /// obstacle ``u, amplitude, frequency, phase``.
    fn reset(&mut self, s0: &Bound<'_, PyAny>, obstacles: &Bound<'_, PyAny>) -> PyResult<()> {
        let s = FloatArray::extract(s0, "s0", 1, "(13,)")?;
        let s: [f64; STATE_DIM] = s
            .values()
            .as_ref()
            .try_into()
            .map_err(|_| PyValueError::new_err(format!("s0: expected {STATE_DIM} values")))?;
        let o = FloatArray::extract(obstacles, "obstacles", 2, "(2, 4)")?;
        if o.shape() != [2, 4] {
            return Err(PyValueError::new_err("obstacles: expected shape (2, 4)"));
        }
        let v = o.values();
        let path = |k: usize| Obstacle {
            u: v[4 * k],
            amplitude: v[4 * k + 1],
            frequency: v[4 * k + 2],
            phase: v[4 * k + 3],
        };
        self.inner.reset(s, [path(0), path(1)]);
        Ok(())
    }

    /// One step for the policy action ``action`` (2,) (scaled from ``[-1, 1]`` to the RL box
    /// unless ``scale`` is false), shielded by ``shield`` when given; ``monitor`` must have read
    /// the current state (its reset or last advance) and moves on to the next.
    #[pyo3(signature = (action, monitor, shield=None, scale=true))]
    fn step(
        &mut self,
        py: Python<'_>,
        action: &Bound<'_, PyAny>,
        monitor: &Bound<'_, PyMonitor>,
        shield: Option<PyRef<'_, PyShield>>,
        scale: bool,
    ) -> PyResult<PyChannelStep> {
        let a = FloatArray::extract(action, "action", 1, "(2,)")?;
        let a = pair(a.values().into_owned(), "action")?;
        let mut monitor = monitor.borrow_mut();
        let step = map(self.inner.step(
            a,
            scale,
            &mut monitor.inner,
            shield.as_deref().map(PyShield::core),
        ))?;
        let obs = self.observation(&monitor.inner);
        Ok(PyChannelStep {
            observation: obs.into_pyarray(py).unbind(),
            a_rl: step.a_rl.to_vec().into_pyarray(py).unbind(),
            action: step.applied.to_vec().into_pyarray(py).unbind(),
            shield: match (shield, step.shield) {
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
            c1: step.measure.h[0],
            c2: step.measure.h[1],
            min_obstacle_distance: step.measure.min_obstacle_distance,
            collision: step.measure.collision,
            violation: step.measure.violation,
        })
    }

    /// The observation at the current state (then the one-hot FSA state of ``monitor``).
    fn observe<'py>(
        &self,
        py: Python<'py>,
        monitor: PyRef<'_, PyMonitor>,
    ) -> Bound<'py, PyArray1<f64>> {
        self.observation(&monitor.inner).into_pyarray(py)
    }

    /// ``(c1, c2, min_obstacle_distance, collision, violation)`` at the current state, the
    /// channel read from ``monitor``'s atoms.
    fn measure(&self, monitor: PyRef<'_, PyMonitor>) -> (f64, f64, f64, bool, bool) {
        let m = self.inner.measure(&monitor.inner);
        (
            m.h[0],
            m.h[1],
            m.min_obstacle_distance,
            m.collision,
            m.violation,
        )
    }

    /// The current state (13,), a copy.
    #[getter]
    fn state<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.state().to_vec().into_pyarray(py)
    }

    /// The obstacles' motion measured over the last step (13,), a copy.
    #[getter]
    fn drift<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.drift().to_vec().into_pyarray(py)
    }

    /// Steps taken in this episode.
    #[getter]
    fn steps(&self) -> u32 {
        self.inner.steps()
    }
}

/// What one ``ChannelWorld.step`` gives.
#[pyclass(name = "ChannelStep", module = "tlshield._core", frozen, get_all)]
pub struct PyChannelStep {
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
    /// Channel constraint c1 at the new state.
    c1: f64,
    /// Channel constraint c2 at the new state.
    c2: f64,
    /// Distance to the nearer obstacle centre.
    min_obstacle_distance: f64,
    /// Closer than the collision distance.
    collision: bool,
    /// Outside the channel.
    violation: bool,
}

/// What one ``step_worlds`` call gives, one row per world (inactive rows: zeros and False).
#[pyclass(name = "WorldsStep", module = "tlshield._core", frozen, get_all)]
pub struct PyWorldsStep {
    /// The observations (N, D), one-hot FSA states included (inactive rows: as given).
    observation: Py<PyArray2<f64>>,
    /// The environments' rewards (N,).
    reward: Py<PyArray1<f64>>,
    /// Episode ended (N,).
    terminated: Py<PyArray1<bool>>,
    /// Horizon reached (N,).
    truncated: Py<PyArray1<bool>>,
    /// FSA states (N,).
    q: Py<PyArray1<i64>>,
    /// Task rewards (N,).
    tl_reward: Py<PyArray1<f64>>,
    /// Task done (N,).
    accepted: Py<PyArray1<bool>>,
    /// In the trap (N,).
    trapped: Py<PyArray1<bool>>,
    /// Channel constraints (N, 2): c1, c2.
    constraints: Py<PyArray2<f64>>,
    /// Distance to the nearer obstacle (N,).
    min_obstacle_distance: Py<PyArray1<f64>>,
    /// In collision (N,).
    collision: Py<PyArray1<bool>>,
    /// Outside the channel (N,).
    violation: Py<PyArray1<bool>>,
    /// RL actions in physical units (N, 2).
    a_rl: Py<PyArray2<f64>>,
    /// Applied actions (N, 2).
    action: Py<PyArray2<f64>>,
    /// Safety corrections (N, 2).
    a_cbf: Py<PyArray2<f64>>,
    /// Task corrections (N, 2).
    a_clf: Py<PyArray2<f64>>,
    /// CLF relaxations (N,).
    delta: Py<PyArray1<f64>>,
    /// Largest barrier slacks (N,).
    slack: Py<PyArray1<f64>>,
    /// ``tlshield.Status`` values (N,) (rows without a shield: 0).
    status: Py<PyArray1<u8>>,
    /// ``tlshield.Solver`` values (N,).
    solver: Py<PyArray1<u8>>,
    /// Whether the row was stepped (N,).
    active: Py<PyArray1<bool>>,
}

/// Steps the worlds in one call (parallel past 32 rows, GIL released): row ``i`` steps
/// ``worlds[i]`` with ``actions[i]`` (scaled from ``[-1, 1]`` unless ``scale`` is false) and
/// ``monitors[i]``, shielded by ``shield``; rows whose ``active`` flag is False are left alone
/// (their ``observation`` row is ``obs[i]`` as given). ``obs`` is ``(N, D)``, the previous
/// observations.
#[pyfunction]
#[pyo3(signature = (worlds, monitors, actions, obs, active=None, shield=None, scale=true))]
#[allow(clippy::too_many_arguments)]
pub fn step_worlds(
    py: Python<'_>,
    worlds: Vec<Bound<'_, PyChannelWorld>>,
    monitors: Vec<Bound<'_, PyMonitor>>,
    actions: &Bound<'_, PyAny>,
    obs: &Bound<'_, PyAny>,
    active: Option<Vec<bool>>,
    shield: Option<PyRef<'_, PyShield>>,
    scale: bool,
) -> PyResult<PyWorldsStep> {
    let rows = worlds.len();
    let borrow_error =
        |what: &str| PyValueError::new_err(format!("{what}: each must appear once (one per row)"));
    let mut world_guards = worlds
        .iter()
        .map(|w| w.try_borrow_mut().map_err(|_| borrow_error("worlds")))
        .collect::<PyResult<Vec<_>>>()?;
    let mut monitor_guards = monitors
        .iter()
        .map(|m| m.try_borrow_mut().map_err(|_| borrow_error("monitors")))
        .collect::<PyResult<Vec<_>>>()?;
    let actions = FloatArray::extract(actions, "actions", 2, "(N, 2)")?;
    let previous = FloatArray::extract(obs, "obs", 2, "(N, D)")?;
    let width = previous.shape()[1];
    let mut observation = previous.values().into_owned();
    let active = active.unwrap_or_else(|| vec![true; rows]);
    let actions = actions.values();
    let mut world_refs: Vec<&mut ChannelWorld> =
        world_guards.iter_mut().map(|g| &mut g.inner).collect();
    let mut monitor_refs: Vec<&mut tlshield_core::Monitor> =
        monitor_guards.iter_mut().map(|g| &mut g.inner).collect();
    let core_shield = shield.as_deref().map(PyShield::core);
    let steps = map(py.detach(|| {
        tlshield_core::channel::step_many(
            &mut world_refs,
            &mut monitor_refs,
            &actions,
            &active,
            scale,
            core_shield,
            &mut observation,
            width,
        )
    }))?;
    let matrix = |v: Vec<f64>, cols: usize| -> PyResult<Py<PyArray2<f64>>> {
        numpy::ndarray::Array2::from_shape_vec((rows, cols), v)
            .map(|a| a.into_pyarray(py).unbind())
            .map_err(|e| PyValueError::new_err(e.to_string()))
    };
    let col = |f: &dyn Fn(&ChannelStep) -> f64| -> Vec<f64> {
        steps.iter().map(|s| s.as_ref().map_or(0.0, f)).collect()
    };
    let flag = |f: &dyn Fn(&ChannelStep) -> bool| -> Vec<bool> {
        steps.iter().map(|s| s.as_ref().is_some_and(f)).collect()
    };
    let pairs = |f: &dyn Fn(&ChannelStep) -> [f64; 2]| -> Vec<f64> {
        steps
            .iter()
            .flat_map(|s| s.as_ref().map_or([0.0, 0.0], f))
            .collect()
    };
    let shield_pair = |f: &dyn Fn(&tlshield_core::Filtered) -> [f64; 2]| -> Vec<f64> {
        pairs(&|s: &ChannelStep| s.shield.as_ref().map_or([0.0, 0.0], f))
    };
    let shield_code = |f: &dyn Fn(&tlshield_core::Filtered) -> u8| -> Vec<u8> {
        steps
            .iter()
            .map(|s| s.as_ref().and_then(|s| s.shield.as_ref()).map_or(0, f))
            .collect()
    };
    Ok(PyWorldsStep {
        observation: matrix(observation, width)?,
        reward: col(&|s| s.reward).into_pyarray(py).unbind(),
        terminated: flag(&|s| s.terminated).into_pyarray(py).unbind(),
        truncated: flag(&|s| s.truncated).into_pyarray(py).unbind(),
        q: steps
            .iter()
            .map(|s| s.as_ref().map_or(0, |s| s.task.q as i64))
            .collect::<Vec<_>>()
            .into_pyarray(py)
            .unbind(),
        tl_reward: col(&|s| s.task.reward).into_pyarray(py).unbind(),
        accepted: flag(&|s| s.task.accepted).into_pyarray(py).unbind(),
        trapped: flag(&|s| s.task.trapped).into_pyarray(py).unbind(),
        constraints: matrix(pairs(&|s| s.measure.h), 2)?,
        min_obstacle_distance: col(&|s| s.measure.min_obstacle_distance)
            .into_pyarray(py)
            .unbind(),
        collision: flag(&|s| s.measure.collision).into_pyarray(py).unbind(),
        violation: flag(&|s| s.measure.violation).into_pyarray(py).unbind(),
        a_rl: matrix(pairs(&|s| s.a_rl), 2)?,
        action: matrix(pairs(&|s| s.applied), 2)?,
        a_cbf: matrix(shield_pair(&|f| [f.a_cbf[0], f.a_cbf[1]]), 2)?,
        a_clf: matrix(shield_pair(&|f| [f.a_clf[0], f.a_clf[1]]), 2)?,
        delta: col(&|s| s.shield.as_ref().map_or(0.0, |f| f.delta))
            .into_pyarray(py)
            .unbind(),
        slack: col(&|s| s.shield.as_ref().map_or(0.0, |f| f.slack))
            .into_pyarray(py)
            .unbind(),
        status: shield_code(&|f| f.status as u8).into_pyarray(py).unbind(),
        solver: shield_code(&|f| f.solver as u8).into_pyarray(py).unbind(),
        active: active.into_pyarray(py).unbind(),
    })
}
