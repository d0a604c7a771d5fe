//! `Monitor`: the task along one episode (core `monitor`), and `TaskStep`, what one step gives.

use numpy::{IntoPyArray, PyArray1};
use pyo3::prelude::*;
use tlshield_core::{Monitor, TaskReward, TaskStep};

use crate::automaton::PyAutomaton;
use crate::convert::vector;
use crate::errors::map;
use crate::progress::PyProgressReward;

/// The task automaton along one episode: it holds the FSA state ``q``, the last reading of the
/// atoms and the task reward's state. ``reset(s0)`` starts an episode and ``advance(s_next)``
/// moves it on; each returns a ``TaskStep`` (``q``, ``reward``, ``accepted``, ``trapped``,
/// ``goal``) from one reading of the atoms, which ``Shield.filter(monitor, a_rl)`` reuses.
/// With ``progress`` (a ``ProgressReward`` of ``automaton``) the reward is the progress-aware
/// one; without it the paper's Eq. 5A1 with weight ``c_r``, ``trap_penalty`` in the trap.
#[pyclass(name = "Monitor", module = "tlshield._core")]
pub struct PyMonitor {
    pub(crate) inner: Monitor,
    automaton: Py<PyAutomaton>,
}

#[pymethods]
impl PyMonitor {
    #[new]
    #[pyo3(
        signature = (automaton, progress=None, *, c_r=1.0, trap_penalty=-100.0),
        text_signature = "(automaton, progress=None, *, c_r=1.0, trap_penalty=-100.0)"
    )]
    fn new(
        automaton: Bound<'_, PyAutomaton>,
        progress: Option<PyRef<'_, PyProgressReward>>,
        c_r: f64,
        trap_penalty: f64,
    ) -> PyResult<Self> {
        let reward = match &progress {
            Some(p) => TaskReward::Progress(p.inner.clone(), p.automaton.clone()),
            None => TaskReward::Paper { c_r, trap_penalty },
        };
        let inner = map(Monitor::new(automaton.get().inner.clone(), reward))?;
        Ok(PyMonitor {
            inner,
            automaton: automaton.unbind(),
        })
    }

    /// Starts an episode at ``s0``: ``q = automaton.step(automaton.initial, s0)``, reward 0.
    fn reset(&mut self, s0: &Bound<'_, PyAny>) -> PyResult<PyTaskStep> {
        let step = map(self.inner.reset(&vector(s0, "s0")?))?;
        Ok(self.report(step))
    }

    /// Reads ``s_next``: moves ``q`` to ``automaton.step(q, s_next)`` and returns that
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
