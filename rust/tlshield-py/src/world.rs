//! `step_worlds`: N bundled worlds of one kind (`ChannelWorld` or `PointMassWorld`) stepped in
//! one call (core `world::step_many`), and `WorldsStep`, what it gives.

use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyList;
use tlshield_core::world::{step_many, ShieldStep, World, WorldStep};

use crate::channel::PyChannelWorld;
use crate::convert::FloatArray;
use crate::errors::map;
use crate::monitor::PyMonitor;
use crate::point_mass::PyPointMassWorld;
use crate::shield::PyShield;

/// Mutable borrows of every object of `list`, each once (a repeated one is an error: one per
/// row).
fn borrow_all<'py, T: pyo3::PyClass<Frozen = pyo3::pyclass::boolean_struct::False>>(
    list: &[Bound<'py, T>],
    what: &str,
) -> PyResult<Vec<PyRefMut<'py, T>>> {
    list.iter()
        .map(|o| {
            o.try_borrow_mut().map_err(|_| {
                PyValueError::new_err(format!("{what}: each must appear once (one per row)"))
            })
        })
        .collect()
}

/// Everything a batch step needs besides the worlds.
struct Rows<'a, 'py> {
    monitors: &'a [Bound<'py, PyMonitor>],
    actions: &'a [f64],
    active: &'a [bool],
    scale: bool,
    shield: Option<&'a tlshield_core::Shield>,
    observation: &'a mut [f64],
    width: usize,
}

/// Steps the worlds of `list` (each `world(object)`) with their monitors, GIL released.
fn step_rows<T, W>(
    py: Python<'_>,
    list: &[Bound<'_, T>],
    world: fn(&mut T) -> &mut W,
    rows: Rows<'_, '_>,
) -> PyResult<Vec<Option<WorldStep>>>
where
    T: pyo3::PyClass<Frozen = pyo3::pyclass::boolean_struct::False>,
    W: World,
{
    let mut world_guards = borrow_all(list, "worlds")?;
    let mut worlds: Vec<&mut W> = world_guards.iter_mut().map(|g| world(g)).collect();
    let mut monitor_guards = borrow_all(rows.monitors, "monitors")?;
    let mut monitors: Vec<&mut tlshield_core::Monitor> =
        monitor_guards.iter_mut().map(|g| &mut g.inner).collect();
    map(py.detach(|| {
        step_many(
            &mut worlds,
            &mut monitors,
            rows.actions,
            rows.active,
            rows.scale,
            rows.shield,
            rows.observation,
            rows.width,
        )
    }))
}

/// What one ``step_worlds`` call gives, one row per world (inactive rows: zeros and False).
#[pyclass(name = "WorldsStep", module = "tlshield._core", frozen, get_all)]
pub struct PyWorldsStep {
    /// The observations (N, D), one-hot FSA states included (inactive rows: as given).
    pub(crate) observation: Py<PyArray2<f64>>,
    /// The environments' rewards (N,).
    pub(crate) reward: Py<PyArray1<f64>>,
    /// Episode ended (N,).
    pub(crate) terminated: Py<PyArray1<bool>>,
    /// Horizon reached (N,).
    pub(crate) truncated: Py<PyArray1<bool>>,
    /// FSA states (N,).
    pub(crate) q: Py<PyArray1<i64>>,
    /// Task rewards (N,).
    pub(crate) tl_reward: Py<PyArray1<f64>>,
    /// Task done (N,).
    pub(crate) accepted: Py<PyArray1<bool>>,
    /// In the trap (N,).
    pub(crate) trapped: Py<PyArray1<bool>>,
    /// Channel constraints (N, 2): c1, c2.
    pub(crate) constraints: Py<PyArray2<f64>>,
    /// Distance to the nearer obstacle (N,).
    pub(crate) min_obstacle_distance: Py<PyArray1<f64>>,
    /// In collision (N,).
    pub(crate) collision: Py<PyArray1<bool>>,
    /// Outside the channel (N,).
    pub(crate) violation: Py<PyArray1<bool>>,
    /// RL actions in physical units (N, 2).
    pub(crate) a_rl: Py<PyArray2<f64>>,
    /// Applied actions (N, 2).
    pub(crate) action: Py<PyArray2<f64>>,
    /// Safety corrections (N, 2).
    pub(crate) a_cbf: Py<PyArray2<f64>>,
    /// Task corrections (N, 2).
    pub(crate) a_clf: Py<PyArray2<f64>>,
    /// CLF relaxations (N,).
    pub(crate) delta: Py<PyArray1<f64>>,
    /// Largest barrier slacks (N,).
    pub(crate) slack: Py<PyArray1<f64>>,
    /// ``tlshield.Status`` values (N,) (rows without a shield: 0).
    pub(crate) status: Py<PyArray1<u8>>,
    /// ``tlshield.Solver`` values (N,).
    pub(crate) solver: Py<PyArray1<u8>>,
    /// Per row, ``(name, slack)`` of the barrier that gave way, or None.
    pub(crate) gave_way: Py<PyList>,
    /// Whether the row was stepped (N,).
    pub(crate) active: Py<PyArray1<bool>>,
}

/// Steps the worlds (all ``ChannelWorld`` or all ``PointMassWorld``) in one call (parallel
/// past 32 rows, GIL released): row ``i`` steps ``worlds[i]`` with ``actions[i]`` (a
/// ChannelWorld scales it from ``[-1, 1]`` unless ``scale`` is false) and
/// ``monitors[i]``, shielded by ``shield``; rows whose ``active`` flag is False are left alone
/// (their ``observation`` row is ``obs[i]`` as given). ``obs`` is ``(N, D)``, the previous
/// observations.
#[pyfunction]
#[pyo3(signature = (worlds, monitors, actions, obs, active=None, shield=None, scale=true))]
#[allow(clippy::too_many_arguments)]
pub fn step_worlds(
    py: Python<'_>,
    worlds: &Bound<'_, PyAny>,
    monitors: &Bound<'_, PyAny>,
    actions: &Bound<'_, PyAny>,
    obs: &Bound<'_, PyAny>,
    active: Option<&Bound<'_, PyAny>>,
    shield: Option<PyRef<'_, PyShield>>,
    scale: bool,
) -> PyResult<PyWorldsStep> {
    let actions = FloatArray::extract(actions, "actions", 2, "(N, 2)")?;
    let previous = FloatArray::extract(obs, "obs", 2, "(N, D)")?;
    let width = previous.shape()[1];
    let monitors: Vec<Bound<'_, PyMonitor>> = crate::convert::sequence(monitors, "monitors")?;
    let mut observation = map(tlshield_core::alloc::try_with_capacity(
        "obs",
        previous.values().len(),
    ))?;
    observation.extend_from_slice(previous.values());
    let actions = actions.values();
    let rows = actions.len() / 2;
    let active = match active {
        Some(a) => crate::convert::sequence(a, "active")?,
        None => map(tlshield_core::alloc::try_vec("actions", rows, true))?,
    };
    let rows = Rows {
        monitors: &monitors,
        actions,
        active: &active,
        scale,
        shield: shield.as_deref().map(PyShield::core),
        observation: &mut observation,
        width,
    };
    let steps = if let Ok(list) = worlds.extract::<Vec<Bound<'_, PyChannelWorld>>>() {
        step_rows(py, &list, |w: &mut PyChannelWorld| &mut w.inner, rows)?
    } else if let Ok(list) = worlds.extract::<Vec<Bound<'_, PyPointMassWorld>>>() {
        step_rows(py, &list, |w: &mut PyPointMassWorld| &mut w.inner, rows)?
    } else {
        return Err(PyTypeError::new_err(
            "worlds: expected a list of ChannelWorld or a list of PointMassWorld (one kind)",
        ));
    };
    let rows = steps.len();
    let matrix = |v: Vec<f64>, cols: usize| -> PyResult<Py<PyArray2<f64>>> {
        numpy::ndarray::Array2::from_shape_vec((rows, cols), v)
            .map(|a| a.into_pyarray(py).unbind())
            .map_err(|e| PyValueError::new_err(e.to_string()))
    };
    let col = |f: &dyn Fn(&WorldStep) -> f64| -> Vec<f64> {
        steps.iter().map(|s| s.as_ref().map_or(0.0, f)).collect()
    };
    let flag = |f: &dyn Fn(&WorldStep) -> bool| -> Vec<bool> {
        steps.iter().map(|s| s.as_ref().is_some_and(f)).collect()
    };
    let pairs = |f: &dyn Fn(&WorldStep) -> [f64; 2]| -> Vec<f64> {
        steps
            .iter()
            .flat_map(|s| s.as_ref().map_or([0.0, 0.0], f))
            .collect()
    };
    let shield_pair = |f: &dyn Fn(&ShieldStep) -> [f64; 2]| -> Vec<f64> {
        pairs(&|s: &WorldStep| s.shield.as_ref().map_or([0.0, 0.0], f))
    };
    let shield_code = |f: &dyn Fn(&ShieldStep) -> u8| -> Vec<u8> {
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
        a_cbf: matrix(shield_pair(&|f| f.a_cbf), 2)?,
        a_clf: matrix(shield_pair(&|f| f.a_clf), 2)?,
        delta: col(&|s| s.shield.as_ref().map_or(0.0, |f| f.delta))
            .into_pyarray(py)
            .unbind(),
        slack: col(&|s| s.shield.as_ref().map_or(0.0, |f| f.slack))
            .into_pyarray(py)
            .unbind(),
        status: shield_code(&|f| f.status as u8).into_pyarray(py).unbind(),
        solver: shield_code(&|f| f.solver as u8).into_pyarray(py).unbind(),
        gave_way: match &shield {
            Some(sh) => sh.gave_way_list(
                py,
                steps.iter().map(|s| {
                    s.as_ref()
                        .and_then(|s| s.shield.as_ref())
                        .and_then(|f| f.gave_way)
                }),
            )?,
            None => PyList::new(py, steps.iter().map(|_| py.None()))?.unbind(),
        },
        active: active.into_pyarray(py).unbind(),
    })
}
