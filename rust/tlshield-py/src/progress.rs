//! `ProgressReward`: the progress-aware task reward of an automaton (core `progress`).

use std::sync::Arc;

use pyo3::prelude::*;
use tlshield_core::{Automaton, ProgressParams, ProgressReward};

use crate::convert::{state, vector};
use crate::errors::map;

/// The progress-aware task reward of an automaton (beyond the paper's Eq. 5A1): a potential
/// ``Phi(s, q) = -rank(q) + x / (scale + |x|)`` with ``x = min(eq5a1(s, q), 0)`` (``rank``:
/// fewest transitions to acceptance), the step reward ``Phi' - Phi - step_cost``, ``bonus``
/// on entering acceptance, ``trap_penalty`` in the trap. Episodes start from ``Phi = 0``.
/// With ``goal_weight = k > 0``: ``Phi = -rank(q) (1 + k span) + x / (scale + |x|) - k
/// min(d, span)``, ``d`` the distance to the CLF goal of ``q`` (``Automaton.goal``), ``span =
/// goal_span``: the CLF's information as potential-based shaping, without its push.
/// ``exclusive``: groups of atom names of which at most one holds at a time (disjoint goal
/// regions), so one state cannot count as reaching two goals. ``step_cost=None`` picks
/// ``(1 - gamma) (max rank + 1)``; ``bonus=None`` picks ``(max rank + 1) gamma^(1 - horizon)``,
/// enough that any trajectory finishing within the horizon out-earns any that does not.
/// Made by ``Automaton.progress_reward``.
#[pyclass(name = "ProgressReward", module = "tlshield._core", frozen)]
pub struct PyProgressReward {
    pub(crate) automaton: Arc<Automaton>,
    pub(crate) inner: ProgressReward,
    /// The parameters it was built with (its pickle rebuilds it from them).
    pub(crate) params: ProgressParams,
}

impl PyProgressReward {
    /// The progress reward of `automaton` (see ``Automaton.progress_reward``).
    pub fn build(
        automaton: Arc<Automaton>,
        params: ProgressParams,
        exclusive: &[Vec<String>],
    ) -> PyResult<Self> {
        let groups = map(automaton.spec().atom_masks(exclusive))?;
        let params = ProgressParams {
            exclusive: groups,
            ..params
        };
        let inner = map(ProgressReward::new(&automaton, &params))?;
        Ok(PyProgressReward {
            automaton,
            inner,
            params,
        })
    }
}

#[pymethods]
impl PyProgressReward {
    /// Fewest transitions from each state to acceptance (None: unreachable, e.g. the trap).
    #[getter]
    fn ranks(&self) -> Vec<Option<u32>> {
        self.inner.ranks().to_vec()
    }

    /// The cost of every step outside acceptance (given or chosen).
    #[getter]
    fn step_cost(&self) -> f64 {
        self.inner.step_cost()
    }

    /// The bonus paid on entering acceptance (given or chosen).
    #[getter]
    fn bonus(&self) -> f64 {
        self.inner.bonus()
    }

    /// The reward of every step in the trap (below any step outside it).
    #[getter]
    fn trap_penalty(&self) -> f64 {
        self.inner.trap_penalty()
    }

    /// The discount the shaping is consistent with.
    #[getter]
    fn gamma(&self) -> f64 {
        self.inner.gamma()
    }

    /// The episode length the bonus is sized for (episodes must not be longer).
    #[getter]
    fn horizon(&self) -> u32 {
        self.inner.horizon()
    }

    /// The goal term's weight per metre (0: none).
    #[getter]
    fn goal_weight(&self) -> f64 {
        self.inner.goal_weight()
    }

    /// The distance beyond which the goal term is flat (metres).
    #[getter]
    fn goal_span(&self) -> f64 {
        self.inner.goal_span()
    }

    /// ``Phi(s, q)``.
    fn potential(&self, s: &Bound<'_, PyAny>, q: &Bound<'_, PyAny>) -> PyResult<f64> {
        let q = state(q, "q", &self.automaton)?;
        let s = vector(s, "s")?;
        Ok(self.inner.potential(&map(self.automaton.read(&s))?, q))
    }

    fn __repr__(&self) -> String {
        let ranks: Vec<String> = self
            .inner
            .ranks()
            .iter()
            .map(|r| r.map_or("None".into(), |r| r.to_string()))
            .collect();
        format!(
            "ProgressReward(ranks=[{}], gamma={}, step_cost={}, bonus={}, trap_penalty={})",
            ranks.join(", "),
            self.inner.gamma(),
            self.inner.step_cost(),
            self.inner.bonus(),
            self.inner.trap_penalty()
        )
    }
}
