//! `Automaton`: the FSA of a spec, its stepper, reward and safe sets.

use std::sync::Arc;

use numpy::{IntoPyArray, PyArray1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString, PyTuple};
use tlshield_core::cnf::{dnf_text, Literal};
use tlshield_core::{progress, Automaton, ProgressParams, Spec, Trajectory};

use crate::convert::{state, vector, FloatArray};
use crate::errors::map;
use crate::literals::LiteralNames;
use crate::pickling::reduce;
use crate::progress::PyProgressReward;
use crate::spec::PySpec;

/// `Spec.automaton()` lives here, next to the type it returns, so that the spec module does not
/// depend on the automaton module (a second `#[pymethods]` block of `PySpec`).
#[pymethods]
impl PySpec {
    /// The finite state automaton of the formula (built once per spec, then shared).
    fn automaton(&self, py: Python<'_>) -> PyResult<PyAutomaton> {
        Ok(PyAutomaton::new(py, self.shared_automaton(py)?))
    }
}

/// `ProgressReward`'s pickle lives here, next to the automaton it is rebuilt from, so that the
/// progress module does not depend on the automaton module.
#[pymethods]
impl PyProgressReward {
    /// Pickled as ``automaton.progress_reward(**its parameters)``, rebuilt on load.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let this = slf.get();
        let p = &this.params;
        let atoms = this.automaton.spec().atoms();
        let exclusive: Vec<Vec<String>> = p
            .exclusive
            .iter()
            .map(|&mask| {
                (0..atoms.len())
                    .filter(|i| mask >> i & 1 == 1)
                    .map(|i| atoms[i].clone())
                    .collect()
            })
            .collect();
        let kwargs = PyDict::new(py);
        kwargs.set_item("gamma", p.gamma)?;
        kwargs.set_item("horizon", p.horizon)?;
        kwargs.set_item("scale", p.scale)?;
        kwargs.set_item("step_cost", p.step_cost)?;
        kwargs.set_item("bonus", p.bonus)?;
        kwargs.set_item("c_r", p.c_r)?;
        kwargs.set_item("exclusive", exclusive)?;
        kwargs.set_item("goal_weight", p.goal_weight)?;
        kwargs.set_item("goal_span", p.goal_span)?;
        let automaton = Bound::new(py, PyAutomaton::new(py, this.automaton.clone()))?;
        let make = automaton.getattr("progress_reward")?;
        reduce(make, PyTuple::empty(py), Some(kwargs), None)
    }
}

/// The finite state automaton of an scTLTL spec (see ``Spec.automaton()``).
#[pyclass(name = "Automaton", module = "tlshield._core", frozen)]
pub struct PyAutomaton {
    pub(crate) inner: Arc<Automaton>,
    /// The literals' text, made once (results reuse it).
    literals: LiteralNames,
}

impl PyAutomaton {
    /// Wraps a built automaton.
    pub fn new(py: Python<'_>, inner: Arc<Automaton>) -> Self {
        let literals = LiteralNames::new(py, inner.spec().atoms());
        PyAutomaton { inner, literals }
    }

    /// A safe set as ``(literal, robustness)`` pairs.
    fn kept<'py>(
        &self,
        py: Python<'py>,
        kept: &[(Literal, f64)],
    ) -> Vec<(Bound<'py, PyString>, f64)> {
        kept.iter()
            .map(|(l, rho)| (self.literals.get(py, l), *rho))
            .collect()
    }

    fn state(&self, q: &Bound<'_, PyAny>) -> PyResult<usize> {
        state(q, "q", &self.inner)
    }
}

#[pymethods]
impl PyAutomaton {
    /// The automaton of a formula alone, its atoms without predicates: states, edges,
    /// ``trap_cnf`` and ``to_dot`` as for any spec of the formula; every method that reads a
    /// state raises ``ValueError`` (build it with ``Spec(formula, predicates).automaton()`` for
    /// those). Raises ``SpecError`` for a bad formula.
    #[staticmethod]
    fn from_formula(py: Python<'_>, formula: &str) -> PyResult<Self> {
        let spec = map(Spec::from_formula(formula))?;
        Ok(PyAutomaton::new(py, crate::spec::interned(py, &spec)?))
    }

    /// Number of states.
    #[getter]
    fn num_states(&self) -> usize {
        self.inner.num_states()
    }

    /// Nodes of the decision diagrams that hold the transition function: what the automaton
    /// stores besides its states and guards (never a ``states x 2**atoms`` table beyond
    /// 65,536 entries).
    #[getter]
    fn diagram_nodes(&self) -> usize {
        self.inner.diagram_nodes()
    }

    /// The state before anything is read; ``q_0 = step(initial, s_0)``.
    #[getter]
    fn initial(&self) -> usize {
        self.inner.initial()
    }

    /// Accepting states (one for a satisfiable formula: absorbing).
    #[getter]
    fn accepting(&self) -> Vec<usize> {
        self.inner.accepting()
    }

    /// The trap state (no path to acceptance), or None.
    #[getter]
    fn trap(&self) -> Option<usize> {
        self.inner.trap()
    }

    /// The atoms, in the order of the spec (bit i of a valuation is atom i).
    #[getter]
    fn atoms(&self) -> Vec<String> {
        self.inner.spec().atoms().to_vec()
    }

    /// The spec the automaton was built from.
    #[getter]
    fn spec(&self) -> PySpec {
        PySpec::from_core(self.inner.spec().clone())
    }

    /// Every edge as ``(src, dst, guard)``, the guard a minimised DNF (``a & !b | c``).
    fn edges(&self) -> Vec<(usize, usize, String)> {
        let atoms = self.inner.spec().atoms();
        self.inner
            .edges()
            .iter()
            .map(|e| (e.src, e.dst, dnf_text(&e.guard, atoms)))
            .collect()
    }

    /// Graphviz DOT text (accepting states double circles, the trap filled red).
    fn to_dot(&self) -> String {
        self.inner.to_dot()
    }

    /// The state after reading state vector ``s`` from state ``q``.
    fn step(&self, s: &Bound<'_, PyAny>, q: &Bound<'_, PyAny>) -> PyResult<usize> {
        let q = self.state(q)?;
        map(self.inner.step(&vector(s, "s")?, q))
    }

    /// Steps many automata at once: ``states`` (B, n), ``qs`` (B,) ints -> (B,) next states.
    /// Parallel, with the GIL released.
    fn step_batch<'py>(
        &self,
        py: Python<'py>,
        states: &Bound<'py, PyAny>,
        qs: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let qs = crate::convert::states(qs, "qs", &self.inner)?;
        let arr = FloatArray::extract(states, "states", 2, "(B, n)")?;
        if arr.shape()[0] != qs.len() {
            return Err(PyValueError::new_err(format!(
                "states: expected {} rows to match qs, got {}",
                qs.len(),
                arr.shape()[0]
            )));
        }
        let dim = arr.shape()[1];
        let values = arr.values();
        let aut = &self.inner;
        let out = py.detach(|| aut.step_batch(&qs, values, dim));
        Ok(map(out)?
            .into_iter()
            .map(|q| q as i64)
            .collect::<Vec<_>>()
            .into_pyarray(py))
    }

    /// The state after reading every row of ``traj`` (T+1, n) from the initial state.
    fn run(&self, traj: &Bound<'_, PyAny>) -> PyResult<usize> {
        let arr = FloatArray::extract(traj, "traj", 2, "(T+1, n)")?;
        let values = arr.values();
        map(self
            .inner
            .run(map(Trajectory::new(values, arr.shape()[1]))?))
    }

    /// Whether the automaton accepts ``traj`` (equals ``Spec.satisfied``).
    fn accepts(&self, traj: &Bound<'_, PyAny>) -> PyResult<bool> {
        let arr = FloatArray::extract(traj, "traj", 2, "(T+1, n)")?;
        let values = arr.values();
        map(self
            .inner
            .accepts(map(Trajectory::new(values, arr.shape()[1]))?))
    }

    /// Eq. 5A1: ``min(rho(s', D_q), c_r * rho(s', !psi_{q,trap}))`` for leaving ``q`` into
    /// ``s_next``; ``rho(s', D_q)`` without a trap edge; 0 in the accepting state;
    /// ``trap_penalty`` in the trap (required there).
    #[pyo3(signature = (s_next, q, c_r, trap_penalty=None))]
    fn reward(
        &self,
        s_next: &Bound<'_, PyAny>,
        q: &Bound<'_, PyAny>,
        c_r: f64,
        trap_penalty: Option<f64>,
    ) -> PyResult<f64> {
        let q = self.state(q)?;
        map(self
            .inner
            .reward(&vector(s_next, "s_next")?, q, c_r, trap_penalty))
    }

    /// The CNF of the negated trap guard of ``q``: clauses of literals (``"c1"``, ``"!g3"``),
    /// empty when ``q`` has no trap edge.
    fn trap_cnf<'py>(
        &self,
        py: Python<'py>,
        q: &Bound<'_, PyAny>,
    ) -> PyResult<Vec<Vec<Bound<'py, PyString>>>> {
        let q = self.state(q)?;
        Ok(map(self.inner.trap_cnf(q))?
            .iter()
            .map(|clause| clause.iter().map(|l| self.literals.get(py, l)).collect())
            .collect())
    }

    /// The trap's recovery safe set: the clauses every state with an edge into the trap keeps
    /// (the intersection of their ``trap_cnf``). A shield in the trap keeps enforcing them, so
    /// a slip (model error, a relaxed step, a start inside a region to avoid) is driven back.
    #[getter]
    fn recovery_cnf<'py>(&self, py: Python<'py>) -> Vec<Vec<Bound<'py, PyString>>> {
        self.inner
            .recovery_cnf()
            .iter()
            .map(|clause| clause.iter().map(|l| self.literals.get(py, l)).collect())
            .collect()
    }

    /// The CNF of the progress-preserving safe set of ``q``: the negation of every guard to a
    /// state farther from acceptance (``ranks``), the trap's included; ``trap_cnf(q)`` where
    /// the trap is the only setback.
    fn avoid_cnf<'py>(
        &self,
        py: Python<'py>,
        q: &Bound<'_, PyAny>,
    ) -> PyResult<Vec<Vec<Bound<'py, PyString>>>> {
        let q = self.state(q)?;
        Ok(map(self.inner.avoid_cnf(q))?
            .iter()
            .map(|clause| clause.iter().map(|l| self.literals.get(py, l)).collect())
            .collect())
    }

    /// Transitions to acceptance per state over the valuations the regions' geometry and the
    /// spec's exclusive groups admit (``None``: unreachable, e.g. the trap).
    #[getter]
    fn ranks(&self) -> Vec<Option<u32>> {
        self.inner.ranks().to_vec()
    }

    /// Eq. 5C1: per clause of ``trap_cnf(q)`` the literal with the largest robustness at ``s``,
    /// as ``(literal, robustness)`` pairs (``("!g3", 2.4)``; empty when ``q`` has no trap
    /// edge), each literal once. ``preserve_progress=True`` reads ``avoid_cnf(q)`` instead
    /// (the shield's default).
    #[pyo3(signature = (s, q, preserve_progress=false))]
    fn safe_set<'py>(
        &self,
        py: Python<'py>,
        s: &Bound<'py, PyAny>,
        q: &Bound<'_, PyAny>,
        preserve_progress: bool,
    ) -> PyResult<Vec<(Bound<'py, PyString>, f64)>> {
        let q = self.state(q)?;
        let kept = map(self.inner.safe_set(&vector(s, "s")?, q, preserve_progress))?;
        Ok(self.kept(py, &kept))
    }

    /// The CLF goal at ``(s, q)`` (paper Eq. 5B1, rank-aware): among ``q``'s edges to states
    /// strictly closer to acceptance, the most robust way a guard cube can hold, and the
    /// deepest point of its regions (the point of largest least robustness); None when ``q``
    /// cannot reach acceptance or no cube has a region.
    fn goal<'py>(
        &self,
        py: Python<'py>,
        s: &Bound<'py, PyAny>,
        q: &Bound<'_, PyAny>,
    ) -> PyResult<Option<Bound<'py, PyArray1<f64>>>> {
        let q = self.state(q)?;
        Ok(map(self.inner.goal(&vector(s, "s")?, q))?.map(|g| g.into_pyarray(py)))
    }

    /// The progress-aware task reward of this automaton (see ``ProgressReward``): ``gamma``
    /// the training discount, ``horizon`` the episode length (the default ``bonus`` is sized
    /// so that finishing within it out-earns not finishing), ``scale`` the Eq. 5A1 value at
    /// which the within-state shaping is halfway down its band, ``exclusive`` groups of atoms
    /// that never hold together beyond those the spec declares (``Spec(..., exclusive=...)``),
    /// which always apply. ``goal_weight`` (> 0) adds potential-based shaping towards the CLF
    /// goal: ``goal_weight`` per metre of approach, flat beyond ``goal_span`` metres.
    #[pyo3(signature = (
        *,
        gamma=progress::DEFAULT_GAMMA,
        horizon=i64::from(progress::DEFAULT_HORIZON),
        scale=progress::DEFAULT_SCALE,
        step_cost=None,
        bonus=None,
        c_r=tlshield_core::monitor::DEFAULT_C_R,
        exclusive=None,
        goal_weight=0.0,
        goal_span=progress::DEFAULT_GOAL_SPAN
    ))]
    #[allow(clippy::too_many_arguments)]
    fn progress_reward(
        &self,
        gamma: f64,
        horizon: i64,
        scale: f64,
        step_cost: Option<f64>,
        bonus: Option<f64>,
        c_r: f64,
        exclusive: Option<&Bound<'_, PyAny>>,
        goal_weight: f64,
        goal_span: f64,
    ) -> PyResult<PyProgressReward> {
        let exclusive = exclusive
            .map(crate::spec::groups_of)
            .transpose()?
            .unwrap_or_default();
        let horizon = u32::try_from(horizon)
            .ok()
            .filter(|h| *h > 0)
            .ok_or_else(|| {
                PyValueError::new_err(format!("horizon = {horizon}: expected a positive integer"))
            })?;
        let params = ProgressParams {
            gamma,
            scale,
            step_cost,
            bonus,
            horizon,
            c_r,
            exclusive: Vec::new(),
            goal_weight,
            goal_span,
        };
        PyProgressReward::build(self.inner.clone(), params, &exclusive)
    }

    /// Pickled as its spec (the formula text and the predicates' numbers) and rebuilt from it
    /// on load: ``Spec.automaton`` for a spec with predicates, ``Automaton.from_formula`` for
    /// a formula alone.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let spec = slf.get().inner.spec();
        if spec.is_bound() {
            let make = py.get_type::<PySpec>().getattr("automaton")?;
            let args = PyTuple::new(py, [Bound::new(py, PySpec::from_core(spec.clone()))?])?;
            return reduce(make, args, None, None);
        }
        let make = slf.get_type().getattr("from_formula")?;
        reduce(make, PyTuple::new(py, [spec.to_string()])?, None, None)
    }

    fn __repr__(&self) -> String {
        let trap = self
            .inner
            .trap()
            .map_or("None".to_string(), |t| t.to_string());
        let atoms: Vec<String> = self
            .inner
            .spec()
            .atoms()
            .iter()
            .map(|a| format!("'{a}'"))
            .collect();
        format!(
            "Automaton(num_states={}, initial={}, accepting={:?}, trap={trap}, atoms=[{}])",
            self.inner.num_states(),
            self.inner.initial(),
            self.inner.accepting(),
            atoms.join(", ")
        )
    }
}
