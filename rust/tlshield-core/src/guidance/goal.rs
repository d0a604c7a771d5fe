//! The CLF goal of Eq. 5B1, rank-aware (beyond the paper): the point the CLF leads towards
//! from an automaton state, a query on a [`Reading`] (the atoms of one state, computed once).
//!
//! Among the state's edges to states strictly closer to acceptance, every way a guard cube can
//! hold (its goal alternatives, built with the automaton) is scored by its least robustness at
//! the state; the goal is the best one's deepest point ([`crate::region`]). The choice is
//! recorded ([`GoalChoice`]) for the shield's goal Jacobian. The router (`super::router`) then
//! leads the CLF around what the shield avoids on the way to this goal.

use smallvec::SmallVec;

use crate::automaton::{Automaton, GoalAlternative, Reading};
use crate::error::AutomatonError;
use crate::predicate::Predicate;
use crate::region;

impl<'a> Reading<'a> {
    /// The CLF goal of Eq. 5B1 at `(s, q)` into `goal`, rank-aware (beyond the paper): among
    /// `q`'s edges to states strictly closer to acceptance ([`Automaton::ranks`]), every way a
    /// guard cube can hold (its non-empty goal alternatives: one part of each union, every part
    /// of each intersection), the most robust at `s` (the first on ties); the goal is that
    /// alternative's deepest point, the point of maximal least robustness of its regions. A
    /// moving alternative whose regions do not meet at this state is passed over, as fixed
    /// empty ones are when the automaton is built. `false` (and `goal` empty) when `q` cannot
    /// reach acceptance or no cube has a region.
    pub fn goal(&self, q: usize, goal: &mut Vec<f64>) -> bool {
        self.goal_space(q, goal).is_some()
    }

    /// The Euclidean distance from this state to the CLF goal of `q` ([`Reading::goal`],
    /// written into `goal`), measured in the goal's space (the position dimensions of its
    /// region); `None` where `q` has no goal.
    pub fn goal_distance(&self, q: usize, goal: &mut Vec<f64>) -> Option<f64> {
        self.goal_distance_in(q, goal).map(|(d, _)| d)
    }

    /// [`Reading::goal_distance`] with the goal's space.
    pub(crate) fn goal_distance_in(
        &self,
        q: usize,
        goal: &mut Vec<f64>,
    ) -> Option<(f64, &'a [usize])> {
        let dims = self.goal_space(q, goal)?;
        let s = self.state();
        let d = dims
            .iter()
            .zip(goal.iter())
            .map(|(&i, g)| (s[i] - g).powi(2))
            .sum::<f64>()
            .sqrt();
        Some((d, dims))
    }

    /// [`Reading::goal`], returning the goal's space (the state dimensions it is a point of).
    fn goal_space(&self, q: usize, goal: &mut Vec<f64>) -> Option<&'a [usize]> {
        self.goal_choice(q, goal).map(|c| c.alt.dims.as_slice())
    }

    /// Whether `point` (over `pos`) lies in the region of the CLF goal of `q`, the alternative
    /// Eq. 5B1 chooses at this state ([`GoalAlternative::holds_at`]). False where `q` has no
    /// goal. Read only where a disc covers the goal, to aim at its free part (`super::free`).
    pub(crate) fn goal_region_holds(
        &self,
        q: usize,
        pos: &[usize; 2],
        point: [f64; 2],
        probe: &mut Vec<f64>,
    ) -> bool {
        self.goal_choice(q, probe)
            .is_some_and(|choice| choice.alt.holds_at(self.state(), pos, point, probe))
    }

    /// [`Reading::goal`], returning how the goal was chosen: the alternative, its lead over the
    /// others, and the better-scored ones passed over as empty here.
    pub(crate) fn goal_choice(&self, q: usize, goal: &mut Vec<f64>) -> Option<GoalChoice<'a>> {
        self.goal_choice_where(q, goal, &mut |_, _| true)
    }

    /// [`Reading::goal_choice`] among the alternatives whose goal `accept` takes (read with the
    /// alternative and its point at this state): the others are passed over as the
    /// empty ones are. `None` (and `goal` empty) where it takes none.
    pub(crate) fn goal_choice_where(
        &self,
        q: usize,
        goal: &mut Vec<f64>,
        accept: &mut dyn FnMut(&'a GoalAlternative, &[f64]) -> bool,
    ) -> Option<GoalChoice<'a>> {
        let (aut, s, rho) = (self.automaton(), self.state(), self.rho());
        goal.clear();
        let ranks = aut.ranks();
        let rank = ranks[q]?;
        // Moving regions are placed at this state; one that is empty here is passed over.
        let mut empty_here: SmallVec<[&'a GoalAlternative; 4]> = SmallVec::new();
        loop {
            let mut best: Option<(&'a GoalAlternative, f64)> = None;
            let mut runner_up = f64::NEG_INFINITY;
            for (e, edge) in aut.edges().iter().enumerate() {
                if edge.src != q || edge.dst == q || ranks[edge.dst].is_none_or(|d| d >= rank) {
                    continue;
                }
                for (cube, alternatives) in edge.guard.iter().zip(aut.goal_alternatives(e)) {
                    let negatives = cube
                        .literals()
                        .filter(|l| !l.positive)
                        .map(|l| l.robustness(rho))
                        .fold(f64::INFINITY, f64::min);
                    for alt in alternatives {
                        if empty_here.iter().any(|x| std::ptr::eq(*x, alt)) {
                            continue;
                        }
                        let score = alt
                            .leaves
                            .iter()
                            .map(|p| p.value(s))
                            .fold(negatives, f64::min);
                        // The first of the largest scores wins (ties keep the earlier one).
                        match best {
                            Some((_, b)) if b >= score => runner_up = runner_up.max(score),
                            _ => {
                                runner_up = best.map_or(runner_up, |(_, b)| runner_up.max(b));
                                best = Some((alt, score));
                            }
                        }
                    }
                }
            }
            let Some((alt, score)) = best else {
                goal.clear();
                return None;
            };
            if alt.place(s, goal) && accept(alt, goal) {
                return Some(GoalChoice {
                    alt,
                    lead: score - runner_up,
                    passed: empty_here,
                });
            }
            goal.clear();
            empty_here.push(alt); // empty at this state, or not taken: the next best
        }
    }
}

/// How [`Reading::goal`] chose its goal at one state (for the shield's goal Jacobian: a choice
/// that no step of a central difference can change needs no difference over the dimensions
/// only the other alternatives read).
#[derive(Debug, Clone)]
pub(crate) struct GoalChoice<'a> {
    alt: &'a GoalAlternative,
    /// The chosen alternative's score minus the best other's not found empty (+inf when alone).
    pub lead: f64,
    /// The better-scored alternatives passed over as empty at this state.
    passed: SmallVec<[&'a GoalAlternative; 4]>,
}

impl GoalChoice<'_> {
    /// Whether every alternative passed over as empty at the chosen state is still empty at
    /// `s`, a state that differs from it only in dimension `d` (one that does not read `d` is
    /// unchanged; the others are placed again, into `spare`).
    pub fn passed_stay_empty(&self, s: &[f64], d: usize, spare: &mut Vec<f64>) -> bool {
        self.passed.iter().all(|a| {
            spare.clear();
            !a.leaves.iter().any(|p| p.reads(d)) || !a.place(s, spare)
        })
    }

    /// Whether the chosen goal moves with state dimension `d` (a moving leaf reads it).
    pub fn reads(&self, d: usize) -> bool {
        self.alt.fixed.is_none() && self.alt.leaves.iter().any(|p| p.reads(d))
    }

    /// The chosen alternative's deepest point at state `s` into `goal`; false (and `goal`
    /// empty) when its regions do not meet there.
    pub fn place(&self, s: &[f64], goal: &mut Vec<f64>) -> bool {
        goal.clear();
        self.alt.place(s, goal)
    }
}

impl GoalAlternative {
    /// Whether `point` (over `pos`) lies in this alternative's region: every region of it holds
    /// at `s` with the position moved to `point` (into `probe`).
    pub(crate) fn holds_at(
        &self,
        s: &[f64],
        pos: &[usize; 2],
        point: [f64; 2],
        probe: &mut Vec<f64>,
    ) -> bool {
        probe.clear();
        probe.extend_from_slice(s);
        probe[pos[0]] = point[0];
        probe[pos[1]] = point[1];
        self.leaves.iter().all(|p| p.value(probe) > 0.0)
    }

    /// This alternative's deepest point at state `s`, appended to the empty `goal`: its fixed
    /// point, the centre of its ball when that is deepest, or the closed form or cone program
    /// of [`region`]; false (and `goal` empty) when its regions do not meet at `s`.
    fn place(&self, s: &[f64], goal: &mut Vec<f64>) -> bool {
        if let Some(x) = &self.fixed {
            goal.extend_from_slice(x);
            return true;
        }
        if region::centre_if_deepest(&self.leaves, &self.dims, s, goal) {
            return true;
        }
        goal.clear();
        if region::separated(&self.leaves, &self.dims, s) {
            return false; // empty in closed form: no cone program this step
        }
        let leaves: SmallVec<[&Predicate; 8]> = self.leaves.iter().collect();
        match region::pieces(&leaves, &self.dims, Some(s))
            .and_then(|pieces| region::deepest_point(&pieces))
        {
            Some((x, depth)) if depth > region::EMPTY_DEPTH => {
                goal.extend_from_slice(&x);
                true
            }
            _ => false,
        }
    }

    /// A bound on how fast any score of the goal's choice moves along state dimension `d`.
    fn score_lipschitz(&self, d: usize) -> f64 {
        self.leaves
            .iter()
            .map(|p| p.lipschitz(d))
            .fold(0.0, f64::max)
    }
}

impl Automaton {
    /// A bound on how fast any score [`Reading::goal`] compares moves along state dimension
    /// `d`: every alternative's leaves and every atom (the negative literals of a cube).
    pub(crate) fn goal_score_lipschitz(&self, d: usize) -> f64 {
        let atoms = self.spec().predicates().iter().map(|p| p.lipschitz(d));
        let leaves = self
            .all_goal_alternatives()
            .iter()
            .flatten()
            .flatten()
            .map(|a| a.score_lipschitz(d));
        atoms.chain(leaves).fold(0.0, f64::max)
    }

    /// The CLF goal of Eq. 5B1 at `(s, q)` ([`Reading::goal`]), checked; `None` without one.
    pub fn goal(&self, s: &[f64], q: usize) -> Result<Option<Vec<f64>>, AutomatonError> {
        self.check_state("q", q)?;
        let mut goal = Vec::new();
        Ok(self.read(s)?.goal(q, &mut goal).then_some(goal))
    }
}
