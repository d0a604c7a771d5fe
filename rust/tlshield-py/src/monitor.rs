//! `Monitor`: the task along one episode (core `monitor`), and `TaskStep`, what one step gives;
//! `MonitorBatch` and `TaskBatch`, their batch twins.

use numpy::{IntoPyArray, PyArray1, PyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};
use tlshield_core::monitor::{DEFAULT_C_R, DEFAULT_TRAP_PENALTY};
use tlshield_core::{Monitor, MonitorBatch, MonitorState, TaskReward, TaskStep};

use crate::automaton::PyAutomaton;
use crate::convert::{vector, FloatArray};
use crate::errors::map;
use crate::pickling::reduce;
use crate::progress::PyProgressReward;
use crate::shield::PyShield;

/// The task automaton along one episode: it holds the FSA state ``q``, the last reading of the
/// atoms and the task reward's state. ``reset(s0)`` starts an episode and ``advance(s_next)``
/// moves it on; each returns a ``TaskStep`` (``q``, ``reward``, ``accepted``, ``trapped``,
/// ``goal``) from one reading of the atoms, which ``Shield.filter_monitor(monitor, a_rl)`` reuses.
/// With ``progress`` (a ``ProgressReward`` of ``automaton``) the reward is the progress-aware
/// one; without it the paper's Eq. 5A1 with weight ``c_r``, ``trap_penalty`` in the trap.
/// With ``routed_by`` (a ``Shield`` of the same automaton whose CLF routes) the goal term of the
/// progress reward and ``goal_distance`` read the way that shield drives around the discs it
/// keeps the robot out of, instead of the straight distance.
#[pyclass(name = "Monitor", module = "tlshield._core")]
pub struct PyMonitor {
    pub(crate) inner: Monitor,
    automaton: Py<PyAutomaton>,
    progress: Option<Py<PyProgressReward>>,
    routed_by: Option<Py<PyShield>>,
}

#[pymethods]
impl PyMonitor {
    #[new]
    #[pyo3(
        signature = (automaton, progress=None, *, c_r=DEFAULT_C_R, trap_penalty=DEFAULT_TRAP_PENALTY, routed_by=None),
        text_signature = "(automaton, progress=None, *, c_r=1.0, trap_penalty=-100.0, routed_by=None)"
    )]
    fn new(
        automaton: Bound<'_, PyAutomaton>,
        progress: Option<PyRef<'_, PyProgressReward>>,
        c_r: f64,
        trap_penalty: f64,
        routed_by: Option<Bound<'_, PyShield>>,
    ) -> PyResult<Self> {
        let reward = task_reward(progress.as_deref(), c_r, trap_penalty);
        let inner = map(Monitor::new(automaton.get().inner.clone(), reward))?;
        let mut monitor = PyMonitor {
            inner,
            automaton: automaton.unbind(),
            progress: progress.map(|p| p.into()),
            routed_by: None,
        };
        monitor.set_routed_by(routed_by)?;
        Ok(monitor)
    }

    /// The shield whose routing the goal term reads (see the class docs), or None: the
    /// straight distance. Set it to route (from the next state read on).
    #[getter]
    fn routed_by(&self, py: Python<'_>) -> Option<Py<PyShield>> {
        self.routed_by.as_ref().map(|s| s.clone_ref(py))
    }

    #[setter]
    fn set_routed_by(&mut self, shield: Option<Bound<'_, PyShield>>) -> PyResult<()> {
        self.inner
            .route_with(routing_of(shield.as_ref(), self.inner.automaton())?);
        self.routed_by = shield.map(Bound::unbind);
        Ok(())
    }

    /// The way from the last state to the CLF goal: the straight distance in the goal's
    /// space, or with ``routed_by`` the length of the way its router plans around the discs;
    /// None without a goal.
    #[getter]
    fn goal_distance(&self) -> Option<f64> {
        self.inner.goal_distance()
    }

    /// Pickled as its constructor's arguments and its state ``(q, phi, started, s)``: a copy
    /// goes on from the same step, bit for bit.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let this = slf.borrow();
        let (args, kwargs) = constructor(
            py,
            &this.automaton,
            this.progress.as_ref(),
            None,
            this.inner.task_reward(),
        )?;
        if let Some(shield) = &this.routed_by {
            kwargs.set_item("routed_by", shield.clone_ref(py))?;
        }
        let state = snapshot_to_python(py, &this.inner.snapshot())?;
        reduce(slf.get_type().into_any(), args, Some(kwargs), Some(state))
    }

    /// Restores a pickled state (see ``__reduce__``).
    fn __setstate__(&mut self, state: &Bound<'_, PyAny>) -> PyResult<()> {
        let state = snapshot_of(state)?;
        map(self.inner.restore(&state))
    }

    /// Starts an episode at ``s0``: ``q = automaton.step(s0, automaton.initial)``, reward 0.
    fn reset(&mut self, s0: &Bound<'_, PyAny>) -> PyResult<PyTaskStep> {
        let step = map(self.inner.reset(&vector(s0, "s0")?))?;
        Ok(self.report(step))
    }

    /// Reads ``s_next``: moves ``q`` to ``automaton.step(s_next, q)`` and returns that
    /// transition's reward, acceptance, the trap and the CLF goal at ``(s_next, q)``.
    fn advance(&mut self, s_next: &Bound<'_, PyAny>) -> PyResult<PyTaskStep> {
        let step = map(self.inner.advance(&vector(s_next, "s_next")?))?;
        Ok(self.report(step))
    }

    /// The current FSA state.
    #[getter]
    fn q(&self) -> usize {
        self.inner.q()
    }

    /// The progress reward's potential at the last state (0 with the paper's reward).
    #[getter]
    fn phi(&self) -> f64 {
        self.inner.phi()
    }

    /// Whether an episode has started.
    #[getter]
    fn started(&self) -> bool {
        self.inner.started()
    }

    /// The automaton monitored.
    #[getter]
    fn automaton(&self, py: Python<'_>) -> Py<PyAutomaton> {
        self.automaton.clone_ref(py)
    }

    /// The last state read (n,).
    #[getter]
    fn state<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.state().to_vec().into_pyarray(py)
    }

    /// The CLF goal (Eq. 5B1, rank-aware) at the last state and ``q``, or None.
    #[getter]
    fn goal<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.inner.goal().map(|g| g.to_vec().into_pyarray(py))
    }

    fn __repr__(&self) -> String {
        let started = if self.inner.started() {
            "True"
        } else {
            "False"
        };
        format!(
            "Monitor(q={}, phi={}, started={started})",
            self.inner.q(),
            self.inner.phi()
        )
    }
}

impl PyMonitor {
    fn report(&self, step: TaskStep) -> PyTaskStep {
        PyTaskStep {
            q: step.q,
            reward: step.reward,
            accepted: step.accepted,
            trapped: step.trapped,
            goal: self.inner.goal().map(<[f64]>::to_vec),
            atoms: self.inner.reading().rho().to_vec(),
        }
    }
}

/// What one step of the task gives (``Monitor.reset`` and ``Monitor.advance``).
#[pyclass(name = "TaskStep", module = "tlshield._core", frozen)]
pub struct PyTaskStep {
    /// The FSA state after reading the state.
    #[pyo3(get)]
    q: usize,
    /// The task reward of the transition (0 at a reset).
    #[pyo3(get)]
    reward: f64,
    /// Whether ``q`` is accepting (the task is done).
    #[pyo3(get)]
    accepted: bool,
    /// Whether ``q`` is the trap (the task can no longer be done).
    #[pyo3(get)]
    trapped: bool,
    goal: Option<Vec<f64>>,
    atoms: Vec<f64>,
}

#[pymethods]
impl PyTaskStep {
    /// The CLF goal at the new state and ``q`` (Eq. 5B1, rank-aware), or None.
    #[getter]
    fn goal<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.goal.as_ref().map(|g| g.clone().into_pyarray(py))
    }

    /// The robustness of every atom at the state read, in the spec's atom order (as
    /// ``Spec.atom_robustness`` gives it).
    #[getter]
    fn atom_robustness<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.atoms.clone().into_pyarray(py)
    }

    fn __repr__(&self) -> String {
        let py_bool = |b: bool| if b { "True" } else { "False" };
        let goal = self.goal.as_ref().map_or("None".to_string(), |g| {
            let values: Vec<String> = g.iter().map(f64::to_string).collect();
            format!("[{}]", values.join(", "))
        });
        format!(
            "TaskStep(q={}, reward={}, accepted={}, trapped={}, goal={goal})",
            self.q,
            self.reward,
            py_bool(self.accepted),
            py_bool(self.trapped),
        )
    }
}

/// ``num`` task monitors of one automaton, stepped together (the batch twin of ``Monitor``,
/// for vector environments): each row's monitor holds its FSA state, so nothing is recovered
/// from observations. ``reset(states, rows=None)`` starts the episodes of ``rows`` (all by
/// default) and ``advance(states)`` moves every row on; both return a ``TaskBatch``, and
/// ``Shield.filter_monitors(monitors, a_rl)`` reuses the rows' readings. Large batches run in
/// parallel with the GIL released. ``routed_by`` is ``Monitor``'s, for every row.
#[pyclass(name = "MonitorBatch", module = "tlshield._core")]
pub struct PyMonitorBatch {
    pub(crate) inner: MonitorBatch,
    automaton: Py<PyAutomaton>,
    progress: Option<Py<PyProgressReward>>,
    routed_by: Option<Py<PyShield>>,
    /// The reward every row pays (kept for the pickle: a batch may have no rows).
    reward: TaskReward,
    steps: Vec<TaskStep>,
}

#[pymethods]
impl PyMonitorBatch {
    #[new]
    #[pyo3(
        signature = (automaton, num, progress=None, *, c_r=DEFAULT_C_R, trap_penalty=DEFAULT_TRAP_PENALTY, routed_by=None),
        text_signature = "(automaton, num, progress=None, *, c_r=1.0, trap_penalty=-100.0, routed_by=None)"
    )]
    fn new(
        automaton: Bound<'_, PyAutomaton>,
        num: usize,
        progress: Option<PyRef<'_, PyProgressReward>>,
        c_r: f64,
        trap_penalty: f64,
        routed_by: Option<Bound<'_, PyShield>>,
    ) -> PyResult<Self> {
        let reward = task_reward(progress.as_deref(), c_r, trap_penalty);
        let inner = map(MonitorBatch::new(
            automaton.get().inner.clone(),
            reward.clone(),
            num,
        ))?;
        let mut batch = PyMonitorBatch {
            inner,
            automaton: automaton.unbind(),
            progress: progress.map(|p| p.into()),
            routed_by: None,
            reward,
            steps: Vec::new(),
        };
        batch.set_routed_by(routed_by)?;
        Ok(batch)
    }

    /// ``Monitor.routed_by``, for every row.
    #[getter]
    fn routed_by(&self, py: Python<'_>) -> Option<Py<PyShield>> {
        self.routed_by.as_ref().map(|s| s.clone_ref(py))
    }

    #[setter]
    fn set_routed_by(&mut self, shield: Option<Bound<'_, PyShield>>) -> PyResult<()> {
        self.inner
            .route_with(routing_of(shield.as_ref(), self.inner.automaton())?);
        self.routed_by = shield.map(Bound::unbind);
        Ok(())
    }

    /// Pickled as its constructor's arguments and every row's state (see ``Monitor``).
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let this = slf.borrow();
        let (args, kwargs) = constructor(
            py,
            &this.automaton,
            this.progress.as_ref(),
            Some(this.inner.len()),
            &this.reward,
        )?;
        if let Some(shield) = &this.routed_by {
            kwargs.set_item("routed_by", shield.clone_ref(py))?;
        }
        let rows = this
            .inner
            .snapshot()
            .iter()
            .map(|row| snapshot_to_python(py, row))
            .collect::<PyResult<Vec<_>>>()?;
        reduce(
            slf.get_type().into_any(),
            args,
            Some(kwargs),
            Some(PyList::new(py, rows)?.into_any()),
        )
    }

    /// Restores a pickled state (see ``__reduce__``).
    fn __setstate__(&mut self, state: &Bound<'_, PyAny>) -> PyResult<()> {
        let rows = state
            .try_iter()?
            .map(|row| snapshot_of(&row?))
            .collect::<PyResult<Vec<_>>>()?;
        map(self.inner.restore(&rows))
    }

    /// Starts the episodes of ``rows`` (distinct row indices; all rows by default) at the rows
    /// of ``states`` ``(len(rows), n)``; returns their ``TaskBatch`` (in the order of ``rows``).
    #[pyo3(signature = (states, rows=None))]
    fn reset(
        &mut self,
        py: Python<'_>,
        states: &Bound<'_, PyAny>,
        rows: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyTaskBatch> {
        let rows = match rows {
            Some(r) => crate::convert::row_indices(r, "rows")?,
            None => (0..self.inner.len()).collect(),
        };
        let arr = FloatArray::extract(states, "states", 2, "(len(rows), n)")?;
        let (dim, values) = (arr.shape()[1], arr.values());
        let (inner, steps) = (&mut self.inner, &mut self.steps);
        map(py.detach(|| inner.reset(&rows, values, dim, steps)))?;
        Ok(PyTaskBatch::new(py, &self.steps))
    }

    /// Moves every row on: row ``i`` reads row ``i`` of ``states`` ``(num, n)``. Every row must
    /// have started. Returns the ``TaskBatch`` of all rows.
    fn advance(&mut self, py: Python<'_>, states: &Bound<'_, PyAny>) -> PyResult<PyTaskBatch> {
        let arr = FloatArray::extract(states, "states", 2, "(num, n)")?;
        let (dim, values) = (arr.shape()[1], arr.values());
        let (inner, steps) = (&mut self.inner, &mut self.steps);
        map(py.detach(|| inner.advance(values, dim, steps)))?;
        Ok(PyTaskBatch::new(py, &self.steps))
    }

    /// Every row's FSA state (num,).
    #[getter]
    fn q<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        let qs: Vec<i64> = self.inner.monitors().iter().map(|m| m.q() as i64).collect();
        qs.into_pyarray(py)
    }

    /// Every row's last state, ``(num, n)`` (a copy; rows not yet reset raise ``ValueError``).
    #[getter]
    fn states<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let monitors = self.inner.monitors();
        if let Some(row) = monitors.iter().position(|m| !m.started()) {
            return map(Err(tlshield_core::AutomatonError::NotReset {
                row: Some(row),
            }));
        }
        let n = monitors.first().map_or(0, |m| m.state().len());
        let values: Vec<f64> = monitors.iter().flat_map(|m| m.state()).copied().collect();
        numpy::ndarray::Array2::from_shape_vec((monitors.len(), n), values)
            .map(|a| a.into_pyarray(py))
            .map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// The automaton monitored.
    #[getter]
    fn automaton(&self, py: Python<'_>) -> Py<PyAutomaton> {
        self.automaton.clone_ref(py)
    }

    fn __len__(&self) -> usize {
        self.inner.len()
    }

    fn __repr__(&self) -> String {
        format!("MonitorBatch(num={})", self.inner.len())
    }
}

/// What one batch step of the task gives, one row per monitor (``MonitorBatch.reset`` and
/// ``MonitorBatch.advance``).
#[pyclass(name = "TaskBatch", module = "tlshield._core", frozen, get_all)]
pub struct PyTaskBatch {
    /// The FSA states (B,).
    q: Py<PyArray1<i64>>,
    /// The task rewards (B,) (0 at a reset).
    reward: Py<PyArray1<f64>>,
    /// Whether each row's task is done (B,).
    accepted: Py<PyArray1<bool>>,
    /// Whether each row is in the trap (B,).
    trapped: Py<PyArray1<bool>>,
}

impl PyTaskBatch {
    fn new(py: Python<'_>, steps: &[TaskStep]) -> Self {
        let column = |f: fn(&TaskStep) -> f64| steps.iter().map(f).collect::<Vec<_>>();
        let flag = |f: fn(&TaskStep) -> bool| steps.iter().map(f).collect::<Vec<_>>();
        PyTaskBatch {
            q: steps
                .iter()
                .map(|s| s.q as i64)
                .collect::<Vec<_>>()
                .into_pyarray(py)
                .unbind(),
            reward: column(|s| s.reward).into_pyarray(py).unbind(),
            accepted: flag(|s| s.accepted).into_pyarray(py).unbind(),
            trapped: flag(|s| s.trapped).into_pyarray(py).unbind(),
        }
    }
}

#[pymethods]
impl PyTaskBatch {
    fn __len__(&self, py: Python<'_>) -> usize {
        self.reward.bind(py).len()
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        format!("TaskBatch(rows={})", self.reward.bind(py).len())
    }
}

/// The arguments that rebuild a monitor (``num`` rows for a batch) paying `reward`.
fn constructor<'py>(
    py: Python<'py>,
    automaton: &Py<PyAutomaton>,
    progress: Option<&Py<PyProgressReward>>,
    num: Option<usize>,
    reward: &TaskReward,
) -> PyResult<(Bound<'py, PyTuple>, Bound<'py, PyDict>)> {
    let mut args = vec![automaton.clone_ref(py).into_bound(py).into_any()];
    if let Some(num) = num {
        args.push(num.into_pyobject(py)?.into_any());
    }
    args.push(progress.map_or_else(
        || py.None().into_bound(py),
        |p| p.clone_ref(py).into_bound(py).into_any(),
    ));
    let kwargs = PyDict::new(py);
    if let TaskReward::Paper { c_r, trap_penalty } = reward {
        kwargs.set_item("c_r", c_r)?;
        kwargs.set_item("trap_penalty", trap_penalty)?;
    }
    Ok((PyTuple::new(py, args)?, kwargs))
}

/// The routing of `shield` for a monitor of `automaton` (None without a shield, or where its
/// CLF does not route); a shield of another automaton is refused, as ``Shield.filter_monitor``
/// refuses it.
fn routing_of(
    shield: Option<&Bound<'_, PyShield>>,
    automaton: &std::sync::Arc<tlshield_core::Automaton>,
) -> PyResult<Option<tlshield_core::route::Routing>> {
    let Some(shield) = shield else {
        return Ok(None);
    };
    let inner = &shield.get().inner;
    if !std::sync::Arc::ptr_eq(inner.automaton(), automaton) {
        return Err(PyValueError::new_err(
            "routed_by: the shield watches another automaton; build the monitor from the \
             shield's automaton (shield.automaton)",
        ));
    }
    Ok(inner.routing().cloned())
}

/// A monitor's state as ``(q, phi, started, s)``.
fn snapshot_to_python<'py>(py: Python<'py>, state: &MonitorState) -> PyResult<Bound<'py, PyAny>> {
    Ok((state.q, state.phi, state.started, state.s.clone())
        .into_pyobject(py)?
        .into_any())
}

/// A monitor's state from ``(q, phi, started, s)``.
fn snapshot_of(state: &Bound<'_, PyAny>) -> PyResult<MonitorState> {
    let (q, phi, started, s): (usize, f64, bool, Bound<'_, PyAny>) =
        state.extract().map_err(|e| {
            PyTypeError::new_err(format!(
                "a monitor's state: expected (q, phi, started, s), got {} ({e})",
                state.repr().map_or_else(|_| "?".into(), |r| r.to_string())
            ))
        })?;
    let s = crate::convert::sequence(&s, "s")?;
    Ok(MonitorState { q, phi, started, s })
}

/// The core's task reward from the Python arguments.
fn task_reward(progress: Option<&PyProgressReward>, c_r: f64, trap_penalty: f64) -> TaskReward {
    match progress {
        Some(p) => TaskReward::Progress(p.inner.clone(), p.automaton.clone()),
        None => TaskReward::Paper { c_r, trap_penalty },
    }
}
