//! `PointMassWorld`: PointMass-v0's world stepped in the core (core `point_mass`; one step
//! gives a `WorldStep`, in `world`).

use numpy::{IntoPyArray, PyArray1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use tlshield_core::point_mass::{self, PointMassParams, PointMassWorld, STATE_DIM};
use tlshield_core::Want;

use crate::convert::FloatArray;
use crate::errors::map;
use crate::monitor::PyMonitor;
use crate::pickling::reduce;
use crate::shield::PyShield;
use crate::world_step::PyWorldStep;

/// ``tlshield/PointMass-v0`` stepped in the core: the shield call, the acceleration box, the
/// double integrator (the shield's model), the walls, the task monitor, the reward and the
/// observation, in one call per step. The Gymnasium class is a shell around it (it draws the
/// start and builds ``info``).
#[pyclass(name = "PointMassWorld", module = "tlshield._core")]
pub struct PyPointMassWorld {
    pub(crate) inner: PointMassWorld,
}

fn values<const N: usize>(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; N]> {
    let arr = FloatArray::extract(obj, name, 1, "(n,)")?;
    arr.values()
        .as_ref()
        .try_into()
        .map_err(|_| PyValueError::new_err(format!("{name}: expected {N} values")))
}

#[pymethods]
impl PyPointMassWorld {
    /// Length of the state vector ``[x, y, vx, vy]`` (the core's `point_mass::STATE_DIM`).
    #[classattr]
    const STATE_DIM: usize = STATE_DIM;

    /// The position's state dimensions ``(x, y)``.
    #[classattr]
    #[allow(non_snake_case)]
    fn POS() -> (usize, usize) {
        (point_mass::POS[0], point_mass::POS[1])
    }

    /// The velocity's state dimensions ``(vx, vy)``.
    #[classattr]
    #[allow(non_snake_case)]
    fn VEL() -> (usize, usize) {
        (point_mass::VEL[0], point_mass::VEL[1])
    }

    #[new]
    #[pyo3(signature = (
        *, dt, horizon, room, max_accel, obstacles, obstacle_radius, collision_penalty
    ))]
    fn new(
        dt: f64,
        horizon: u32,
        room: (f64, f64),
        max_accel: f64,
        obstacles: ((f64, f64), (f64, f64)),
        obstacle_radius: f64,
        collision_penalty: f64,
    ) -> Self {
        let ((x1, y1), (x2, y2)) = obstacles;
        PyPointMassWorld {
            inner: PointMassWorld::new(PointMassParams {
                dt,
                horizon,
                room,
                max_accel,
                obstacles: [[x1, y1], [x2, y2]],
                obstacle_radius,
                collision_penalty,
            }),
        }
    }

    /// Pickled as its constructor's arguments and its state ``(s, t)``.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let world = &slf.borrow().inner;
        let p = world.params();
        let kwargs = PyDict::new(py);
        kwargs.set_item("dt", p.dt)?;
        kwargs.set_item("horizon", p.horizon)?;
        kwargs.set_item("room", p.room)?;
        kwargs.set_item("max_accel", p.max_accel)?;
        let [[x1, y1], [x2, y2]] = p.obstacles;
        kwargs.set_item("obstacles", ((x1, y1), (x2, y2)))?;
        kwargs.set_item("obstacle_radius", p.obstacle_radius)?;
        kwargs.set_item("collision_penalty", p.collision_penalty)?;
        let state = (world.state().to_vec(), world.steps()).into_pyobject(py)?;
        reduce(
            slf.get_type().into_any(),
            PyTuple::empty(py),
            Some(kwargs),
            Some(state.into_any()),
        )
    }

    /// Restores a pickled state ``(s, t)``.
    fn __setstate__(&mut self, state: &Bound<'_, PyAny>) -> PyResult<()> {
        let (s, t): (Bound<'_, PyAny>, u32) = state.extract()?;
        map(self.inner.restore(values::<STATE_DIM>(&s, "s")?, t))
    }

    /// Starts an episode at ``s0`` (4,): ``x, y, vx, vy``.
    fn reset(&mut self, s0: &Bound<'_, PyAny>) -> PyResult<()> {
        self.inner.reset(values::<STATE_DIM>(s0, "s0")?);
        Ok(())
    }

    /// One step for the RL action ``a_rl`` (2,), shielded by ``shield`` when given;
    /// ``monitor`` must have read the current state (its reset or last advance) and moves on.
    #[pyo3(signature = (a_rl, monitor, shield=None))]
    fn step(
        &mut self,
        py: Python<'_>,
        a_rl: &Bound<'_, PyAny>,
        monitor: &Bound<'_, PyMonitor>,
        shield: Option<PyRef<'_, PyShield>>,
    ) -> PyResult<PyWorldStep> {
        let a = values::<2>(a_rl, "a_rl")?;
        let mut monitor = monitor.borrow_mut();
        let step = map(self.inner.step(
            a,
            &mut monitor.inner,
            shield.as_deref().map(PyShield::core),
            Want::Record,
        ))?;
        let n = monitor.inner.automaton().num_states();
        let mut obs = vec![0.0; STATE_DIM + n];
        self.inner.observe(&monitor.inner, n, &mut obs);
        PyWorldStep::new(py, step, obs, shield)
    }

    /// ``(h_o1, h_o2, min_obstacle_distance, collision)`` at the current state (the
    /// obstacles' clearances, distance minus radius; the smaller; inside an obstacle).
    fn measure(&self) -> (f64, f64, f64, bool) {
        let m = self.inner.measure();
        (m.h[0], m.h[1], m.min_obstacle_distance, m.collision)
    }

    /// The current state (4,), a copy.
    #[getter]
    fn state<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.state().to_vec().into_pyarray(py)
    }

    /// Steps taken in this episode.
    #[getter]
    fn steps(&self) -> u32 {
        self.inner.steps()
    }
}
