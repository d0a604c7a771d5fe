//! The automaton's guidance of the learner and the shield, one equation each: the
//! FSA-augmented reward (Eq. 5A1), the CLF goal (Eq. 5B1) and the CBF safe set (Eq. 5C1).
//! Each is a query on a [`Reading`] (the atoms of one state, computed once); the checked
//! `Automaton` methods validate their inputs and read the state themselves.

use smallvec::SmallVec;

use super::regions::GoalAlternative;
use super::{Automaton, Reading};
use crate::cnf::{self, Literal};
use crate::error::{AutomatonError, InputError};
use crate::predicate::{Center, Predicate};
use crate::region;

/// The default weight `c_r` of Eq. 5A1's trap term (the paper's task reward).
pub const DEFAULT_C_R: f64 = 1.0;
/// The default reward of a step in the trap (the paper's task reward).
pub const DEFAULT_TRAP_PENALTY: f64 = -100.0;

impl<'a> Reading<'a> {
    /// The Eq. 5A1 value of being in `q` at this state:
    /// `min(rho(s, D_q), c_r * rho(s, !psi_{q,trap}))`, `rho(s, D_q)` without a trap edge, 0 in
    /// an accepting state and -inf in the trap (no progress is possible; the checked
    /// [`Automaton::reward`] substitutes the trap penalty). `c_r` is trusted to be > 0.
    #[inline]
    pub fn reward(&self, q: usize, c_r: f64) -> f64 {
        let aut = self.aut;
        if aut.accepting[q] {
            return 0.0;
        }
        let rho = self.rho();
        let progress = cnf::dnf_robustness(&aut.progress[q], rho);
        if aut.trap_cnf[q].is_empty() {
            progress
        } else {
            progress.min(c_r * cnf::cnf_robustness(&aut.trap_cnf[q], rho))
        }
    }

    /// [`Reading::reward`] over the cubes of `D_q` that can hold where they lead: a cube whose
    /// positive Ball literal (a goal) has its centre violating one of the cube's other literals
    /// (e.g. a goal disc wholly outside the channel the cube also requires) is left out, so
    /// shaping does not pull towards a goal the task cannot take. When every cube is left out,
    /// all count (the plain Eq. 5A1 value). The progress reward's within-state potential.
    pub fn reachable_reward(&self, q: usize, c_r: f64) -> f64 {
        let aut = self.aut;
        if aut.accepting[q] {
            return 0.0;
        }
        let (s, rho, predicates) = (self.s, self.rho(), aut.spec.predicates());
        let mut at_goal: SmallVec<[f64; 32]> = SmallVec::from_slice(s);
        let mut best = f64::NEG_INFINITY;
        let mut any = false;
        for cube in &aut.progress[q] {
            let ball = cube.literals().find_map(|l| match &predicates[l.atom] {
                Predicate::Ball(b) if l.positive && b.offset().is_none() => Some((l.atom, b)),
                _ => None,
            });
            if let Some((atom, ball)) = ball {
                at_goal.copy_from_slice(s);
                for (k, &i) in ball.pos().iter().enumerate() {
                    at_goal[i] = match ball.center() {
                        Center::Fixed(c) => c[k],
                        Center::Dims(d) => s[d[k]],
                    };
                }
                let blocked = cube.literals().filter(|l| l.atom != atom).any(|l| {
                    let value = predicates[l.atom].value(&at_goal);
                    (if l.positive { value } else { -value }) < 0.0
                });
                if blocked {
                    continue;
                }
            }
            any = true;
            best = best.max(cube.robustness(rho));
        }
        if !any {
            return self.reward(q, c_r);
        }
        if aut.trap_cnf[q].is_empty() {
            best
        } else {
            best.min(c_r * cnf::cnf_robustness(&aut.trap_cnf[q], rho))
        }
    }

    /// The CBF safe set of Eq. 5C1 at `(s, q)` into `out`: per clause of the negated trap
    /// guard, the literal with the LARGEST robustness (the first on ties) and that robustness;
    /// empty without a trap edge. In the trap itself: its recovery safe set (beyond the paper,
    /// which leaves the trap unshielded). The paper prints argmin, which would keep e.g. "be inside g3"
    /// for the clause (g3 | c1); argmax keeps the literal that holds with the largest margin.
    /// A literal chosen by two clauses appears once.
    pub fn safe_set(&self, q: usize, out: &mut Vec<(Literal, f64)>) {
        self.choose(self.clauses(q, &self.aut.trap_cnf), out);
    }

    /// The progress-preserving safe set (beyond the paper): [`Reading::safe_set`] over the
    /// avoid CNF of `q`, which also keeps the state out of the guards of edges that would set
    /// the task back (to a state farther from acceptance). Equal to the Eq. 5C1 safe set where
    /// the trap is the only setback.
    pub fn progress_safe_set(&self, q: usize, out: &mut Vec<(Literal, f64)>) {
        self.choose(self.clauses(q, &self.aut.avoid_cnf), out);
    }

    /// `per_state[q]`, or in the trap its recovery safe set ([`Automaton::recovery_cnf`]): no
    /// state of the task turns the shield off.
    fn clauses<'b>(&'b self, q: usize, per_state: &'b [Vec<Vec<Literal>>]) -> &'b [Vec<Literal>] {
        if Some(q) == self.aut.trap {
            &self.aut.recovery_cnf
        } else {
            &per_state[q]
        }
    }

    fn choose(&self, clauses: &[Vec<Literal>], out: &mut Vec<(Literal, f64)>) {
        let rho = self.rho();
        out.clear();
        for clause in clauses {
            let (lit, h) = clause
                .iter()
                .map(|l| (*l, l.robustness(rho)))
                .fold(None, first_max)
                .expect("clauses are never empty");
            if !out.iter().any(|(l, _)| *l == lit) {
                out.push((lit, h));
            }
        }
    }

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
        let s = self.s;
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

    /// [`Reading::goal`], returning how the goal was chosen: the alternative, its lead over the
    /// others, and the better-scored ones passed over as empty here.
    pub(crate) fn goal_choice(&self, q: usize, goal: &mut Vec<f64>) -> Option<GoalChoice<'a>> {
        let (aut, s, rho) = (self.aut, self.s, self.rho());
        goal.clear();
        let rank = aut.ranks[q]?;
        // Moving regions are placed at this state; one that is empty here is passed over.
        let mut empty_here: SmallVec<[&'a GoalAlternative; 4]> = SmallVec::new();
        loop {
            let mut best: Option<(&'a GoalAlternative, f64)> = None;
            let mut runner_up = f64::NEG_INFINITY;
            for (e, edge) in aut.edges.iter().enumerate() {
                if edge.src != q || edge.dst == q || aut.ranks[edge.dst].is_none_or(|d| d >= rank) {
                    continue;
                }
                for (cube, alternatives) in edge.guard.iter().zip(&aut.goal_alternatives[e]) {
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
            let (alt, score) = best?;
            if alt.place(s, goal) {
                return Some(GoalChoice {
                    alt,
                    lead: score - runner_up,
                    passed: empty_here,
                });
            }
            empty_here.push(alt); // empty at this state: the next best
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
        let atoms = self.spec.predicates().iter().map(|p| p.lipschitz(d));
        let leaves = self
            .goal_alternatives
            .iter()
            .flatten()
            .flatten()
            .map(|a| a.score_lipschitz(d));
        atoms.chain(leaves).fold(0.0, f64::max)
    }

    /// The FSA-augmented reward of Eq. 5A1 for leaving `q` into state `s_next`
    /// ([`Reading::reward`]), `trap_penalty` in the trap (an error when it is `None`).
    pub fn reward(
        &self,
        s_next: &[f64],
        q: usize,
        c_r: f64,
        trap_penalty: Option<f64>,
    ) -> Result<f64, AutomatonError> {
        self.check_state("q", q)?;
        let reading = self.read(s_next)?;
        check_weight(c_r)?;
        if Some(q) == self.trap {
            return trap_reward(q, trap_penalty);
        }
        Ok(reading.reward(q, c_r))
    }

    /// The CBF safe set of Eq. 5C1 at `(s, q)` ([`Reading::safe_set`]), or with
    /// `preserve_progress` the progress-preserving one ([`Reading::progress_safe_set`]),
    /// checked.
    pub fn safe_set(
        &self,
        s: &[f64],
        q: usize,
        preserve_progress: bool,
    ) -> Result<Vec<(Literal, f64)>, AutomatonError> {
        self.check_state("q", q)?;
        let reading = self.read(s)?;
        let mut out = Vec::with_capacity(self.avoid_cnf[q].len());
        if preserve_progress {
            reading.progress_safe_set(q, &mut out);
        } else {
            reading.safe_set(q, &mut out);
        }
        Ok(out)
    }

    /// The CLF goal of Eq. 5B1 at `(s, q)` ([`Reading::goal`]), checked; `None` without one.
    pub fn goal(&self, s: &[f64], q: usize) -> Result<Option<Vec<f64>>, AutomatonError> {
        self.check_state("q", q)?;
        let mut goal = Vec::new();
        Ok(self.read(s)?.goal(q, &mut goal).then_some(goal))
    }
}

fn check_weight(c_r: f64) -> Result<(), AutomatonError> {
    if c_r.is_finite() && c_r > 0.0 {
        return Ok(());
    }
    Err(InputError::Value {
        what: "c_r".into(),
        expected: "a finite weight > 0".into(),
        got: c_r.to_string(),
    }
    .into())
}

fn trap_reward(q: usize, trap_penalty: Option<f64>) -> Result<f64, AutomatonError> {
    match trap_penalty {
        Some(p) if p.is_finite() => Ok(p),
        Some(p) => Err(InputError::NonFinite {
            what: "trap_penalty".into(),
            value: p,
        }
        .into()),
        None => Err(AutomatonError::TrapReward(q)),
    }
}

/// Fold step keeping the first item with the largest score: `iter.fold(None, first_max)`.
/// Ties keep the earlier item, so choices are deterministic.
fn first_max<T>(best: Option<(T, f64)>, cur: (T, f64)) -> Option<(T, f64)> {
    match best {
        Some(b) if b.1 >= cur.1 => Some(b),
        _ => Some(cur),
    }
}
