//! `ChannelWorld`: the case study's world stepped in the core (core `channel`; one step gives a
//! `WorldStep`, and `step_worlds` steps many: both in `world`).

use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use tlshield_core::channel::{
    self, ChannelParams, ChannelState, ChannelWorld, Obstacle, STATE_DIM,
};
use tlshield_core::Want;

use crate::convert::{sequence, FloatArray};
use crate::dynamics::PyUnicycle;
use crate::errors::map;
use crate::monitor::PyMonitor;
use crate::pickling::reduce;
use crate::shield::PyShield;
use crate::world_step::PyWorldStep;

/// The paper's case study (Sec. VI) stepped in the core: the plant (through ``model``, the
/// shield's model), the obstacles, the shield call, the task monitor, the reward terms and the
/// observation, in one call per step. ``tlshield/Channel-v0`` is a Gymnasium shell around it
/// (it draws the episodes and builds ``info``).
#[pyclass(name = "ChannelWorld", module = "tlshield._core")]
pub struct PyChannelWorld {
    pub(crate) inner: ChannelWorld,
    /// The `ChannelParams` it was built from (pickled with it).
    params: Py<PyAny>,
}

fn pair(values: Vec<f64>, name: &str) -> PyResult<[f64; 2]> {
    <[f64; 2]>::try_from(values)
        .map_err(|v| PyValueError::new_err(format!("{name}: expected 2 values, got {}", v.len())))
}

/// `params.group.name` of a `ChannelParams`, converted; a missing field or a value of
/// another kind is a `TypeError` naming it.
fn setting<'py, T: for<'a> FromPyObject<'a, 'py>>(
    params: &Bound<'py, PyAny>,
    group: &str,
    name: &str,
    expected: &str,
) -> PyResult<T> {
    let value = params
        .getattr(group)
        .and_then(|g| g.getattr(name))
        .map_err(|_| {
            PyTypeError::new_err(format!(
                "params: expected a ChannelParams (no {group}.{name})"
            ))
        })?;
    value
        .extract()
        .map_err(|_| PyTypeError::new_err(format!("params.{group}.{name}: expected {expected}")))
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
    /// Length of the state vector (the core's `channel::STATE_DIM`).
    #[classattr]
    const STATE_DIM: usize = channel::STATE_DIM;
    /// Length of the relative observation before the one-hot FSA state.
    #[classattr]
    const RELATIVE_DIM: usize = channel::RELATIVE_DIM;
    /// Index of the reference point's x.
    #[classattr]
    const X: usize = channel::X;
    /// Index of the reference point's y.
    #[classattr]
    const Y: usize = channel::Y;
    /// Index of the heading.
    #[classattr]
    const THETA: usize = channel::THETA;

    /// The (x, y) indices of the goals g1, g2, g3.
    #[classattr]
    #[allow(non_snake_case)]
    fn GOAL_DIMS() -> Vec<(usize, usize)> {
        channel::GOAL_DIMS.iter().map(|d| (d[0], d[1])).collect()
    }

    /// The (x, y) indices of the obstacles o1, o2.
    #[classattr]
    #[allow(non_snake_case)]
    fn OBSTACLE_DIMS() -> Vec<(usize, usize)> {
        channel::OBSTACLE_DIMS
            .iter()
            .map(|d| (d[0], d[1]))
            .collect()
    }

    /// Channel coordinates ``(u, v)`` to ``(x, y)`` (the core's own).
    #[staticmethod]
    fn xy(u: f64, v: f64) -> (f64, f64) {
        let [x, y] = channel::xy(u, v);
        (x, y)
    }

    /// The RL actions in physical units of policy actions ``(N, 2)`` in ``[-1, 1]^2``
    /// (clipped), scaled exactly as a step scales them.
    fn rl_action<'py>(
        &self,
        py: Python<'py>,
        action: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let p = self.inner.params();
        let a = FloatArray::extract(action, "action", 2, "(N, 2)")?;
        if a.shape()[1] != 2 {
            return Err(PyValueError::new_err(format!(
                "action: expected (N, 2), got {}",
                crate::convert::shape_text(a.shape())
            )));
        }
        let out: Vec<f64> = a
            .values()
            .chunks(2)
            .flat_map(|c| p.rl_action([c[0], c[1]]))
            .collect();
        numpy::ndarray::Array2::from_shape_vec((a.shape()[0], 2), out)
            .map(|array| array.into_pyarray(py))
            .map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// The world of ``model`` under ``params`` (a ``tlshield.envs.ChannelParams``: every
    /// field the world reads is taken from it by name), in evaluation or training, with the
    /// channel atoms' indices in the automaton.
    #[new]
    #[pyo3(signature = (model, params, *, evaluation, channel_atoms))]
    fn new(
        model: PyRef<'_, PyUnicycle>,
        params: &Bound<'_, PyAny>,
        evaluation: bool,
        channel_atoms: (usize, usize),
    ) -> PyResult<Self> {
        const NUMBER: &str = "a number";
        const FLAG: &str = "a bool";
        let p = params;
        let rl_bounds: (Bound<'_, PyAny>, Bound<'_, PyAny>) =
            setting(p, "agent", "rl_bounds", "a pair (lo, hi)")?;
        let kind: String = setting(p, "observation", "kind", "a str")?;
        let core = ChannelParams {
            dt: setting(p, "agent", "dt", NUMBER)?,
            horizon: setting(p, "task", "horizon", "a whole number in [0, 2**32)")?,
            arena: setting(p, "agent", "arena", "a pair of numbers")?,
            half_width: setting(p, "task", "half_width", NUMBER)?,
            obstacle_radius: setting(p, "obstacles", "obstacle_radius", NUMBER)?,
            safe_distance: setting(p, "obstacles", "safe_distance", NUMBER)?,
            w: setting(p, "obstacles", "w", NUMBER)?,
            collision_penalty: setting(p, "obstacles", "collision_penalty", NUMBER)?,
            intervention_penalty: setting(p, "shield", "intervention_penalty", NUMBER)?,
            relative: kind == "relative",
            rl_bounds: (
                pair(sequence(&rl_bounds.0, "rl_bounds[0]")?, "rl_bounds[0]")?,
                pair(sequence(&rl_bounds.1, "rl_bounds[1]")?, "rl_bounds[1]")?,
            ),
            obstacle_drift: setting(p, "shield", "obstacle_drift", FLAG)?,
            evaluation,
            end_on_trap: setting(p, "task", "end_on_trap", FLAG)?,
            channel_atoms: [channel_atoms.0, channel_atoms.1],
        };
        Ok(PyChannelWorld {
            inner: ChannelWorld::new(core, model.inner.clone()),
            params: params.clone().unbind(),
        })
    }

    /// Pickled as its constructor's arguments (the model and the params object) and its state
    /// ``(s, drift, obstacles, t)``.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let world = &slf.borrow().inner;
        let p = world.params();
        let kwargs = PyDict::new(py);
        kwargs.set_item("evaluation", p.evaluation)?;
        kwargs.set_item("channel_atoms", (p.channel_atoms[0], p.channel_atoms[1]))?;
        let model = crate::dynamics::to_python(py, world.model())?;
        let snap = world.snapshot();
        let paths: Vec<[f64; 4]> = snap
            .obstacles
            .iter()
            .map(|o| [o.u, o.amplitude, o.frequency, o.phase])
            .collect();
        let state = (snap.s.to_vec(), snap.drift.to_vec(), paths, snap.t).into_pyobject(py)?;
        reduce(
            slf.get_type().into_any(),
            PyTuple::new(py, [model, slf.borrow().params.bind(py).clone()])?,
            Some(kwargs),
            Some(state.into_any()),
        )
    }

    /// Restores a pickled state ``(s, drift, obstacles, t)``.
    fn __setstate__(&mut self, state: &Bound<'_, PyAny>) -> PyResult<()> {
        type State<'py> = (Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>, u32);
        let (s, drift, paths, t): State<'_> = state.extract()?;
        let (s, drift) = (sequence(&s, "s")?, sequence(&drift, "drift")?);
        let paths: Vec<[f64; 4]> = sequence(&paths, "obstacles")?;
        if paths.len() != 2 {
            return Err(PyValueError::new_err(format!(
                "obstacles: expected 2 paths, got {}",
                paths.len()
            )));
        }
        let full = |v: Vec<f64>, name: &str| -> PyResult<[f64; STATE_DIM]> {
            v.try_into()
                .map_err(|_| PyValueError::new_err(format!("{name}: expected {STATE_DIM} values")))
        };
        let path = |k: usize| -> PyResult<Obstacle> {
            let [u, amplitude, frequency, phase] = *paths
                .get(k)
                .ok_or_else(|| PyValueError::new_err("obstacles: expected 2 paths"))?;
            Ok(Obstacle {
                u,
                amplitude,
                frequency,
                phase,
            })
        };
        let snap = ChannelState {
            s: full(s, "s")?,
            drift: full(drift, "drift")?,
            obstacles: [path(0)?, path(1)?],
            t,
        };
        map(self.inner.restore(&snap))
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
    ) -> PyResult<PyWorldStep> {
        let a = FloatArray::extract(action, "action", 1, "(2,)")?;
        let a = pair(a.values().to_vec(), "action")?;
        let mut monitor = monitor.borrow_mut();
        let step = map(self.inner.step(
            a,
            scale,
            &mut monitor.inner,
            shield.as_deref().map(PyShield::core),
            Want::Record,
        ))?;
        let obs = self.observation(&monitor.inner);
        PyWorldStep::new(py, step, obs, shield)
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
