//! The automaton's guidance of the learner and the shield, one equation each: the
//! FSA-augmented reward (Eq. 5A1), the CLF goal (Eq. 5B1) and the CBF safe set (Eq. 5C1).
//! Each is a query on a [`Reading`] (the atoms of one state, computed once); the checked
//! `Automaton` methods validate their inputs and read the state themselves.

use smallvec::SmallVec;

use super::{Automaton, Reading};
use crate::cnf::{self, Cube, Literal};
use crate::error::{AutomatonError, InputError};
use crate::predicate::{Center, Predicate};

impl Reading<'_> {
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
                Predicate::Ball(b) if l.positive => Some((l.atom, b)),
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
    /// empty without a trap edge. The paper prints argmin, which would keep e.g. "be inside g3"
    /// for the clause (g3 | c1); argmax keeps the literal that holds with the largest margin.
    pub fn safe_set(&self, q: usize, out: &mut Vec<(Literal, f64)>) {
        let rho = self.rho();
        out.clear();
        out.extend(self.aut.trap_cnf[q].iter().map(|clause| {
            clause
                .iter()
                .map(|l| (*l, l.robustness(rho)))
                .fold(None, first_max)
                .expect("clauses are never empty")
        }));
    }

    /// The CLF goal of Eq. 5B1 at `(s, q)` into `goal`: among `q`'s edges to other non-trap
    /// states the one whose guard has the largest robustness (the first on ties), in its DNF the
    /// cube with the largest robustness, and the mean of the centres of that cube's positive
    /// Ball literals. `false` (and `goal` empty) when there is no such edge or the cube has no
    /// positive Ball literal.
    pub fn goal(&self, q: usize, goal: &mut Vec<f64>) -> bool {
        let (aut, s, rho) = (self.aut, self.s, self.rho());
        goal.clear();
        let Some((cube, _)) = aut
            .edges
            .iter()
            .filter(|e| e.src == q && e.dst != q && Some(e.dst) != aut.trap)
            .filter_map(|e| best_cube(&e.guard, rho))
            .fold(None, first_max)
        else {
            return false;
        };
        let mut count = 0.0;
        for lit in cube.literals().filter(|l| l.positive) {
            if let Predicate::Ball(ball) = &aut.spec.predicates()[lit.atom] {
                let len = ball.pos().len();
                if count == 0.0 {
                    goal.resize(len, 0.0);
                } else if goal.len() != len {
                    continue;
                }
                match ball.center() {
                    Center::Fixed(c) => goal.iter_mut().zip(c).for_each(|(a, b)| *a += b),
                    Center::Dims(d) => goal.iter_mut().zip(d).for_each(|(a, &i)| *a += s[i]),
                }
                count += 1.0;
            }
        }
        if count == 0.0 {
            goal.clear();
            return false;
        }
        goal.iter_mut().for_each(|v| *v /= count);
        true
    }
}

impl Automaton {
    /// The FSA-augmented reward of Eq. 5A1 for leaving `q` into state `s_next`
    /// ([`Reading::reward`]), `trap_penalty` in the trap (an error when it is `None`).
    pub fn reward(
        &self,
        q: usize,
        s_next: &[f64],
        c_r: f64,
        trap_penalty: Option<f64>,
    ) -> Result<f64, AutomatonError> {
        self.check_state("q", q as i64)?;
        let reading = self.read(s_next)?;
        check_weight(c_r)?;
        if Some(q) == self.trap {
            return trap_reward(q, trap_penalty);
        }
        Ok(reading.reward(q, c_r))
    }

    /// One step of the FSA-augmented loop from one reading of `s_next`: the next state
    /// `q' = step(q, s_next)`, the reward of Eq. 5A1 for leaving `q` ([`Automaton::reward`]),
    /// and the safe set at `(s_next, q')` written into `safe` ([`Reading::safe_set`]).
    pub fn advance(
        &self,
        q: usize,
        s_next: &[f64],
        c_r: f64,
        trap_penalty: Option<f64>,
        safe: &mut Vec<(Literal, f64)>,
    ) -> Result<(usize, f64), AutomatonError> {
        self.check_state("q", q as i64)?;
        let reading = self.read(s_next)?;
        check_weight(c_r)?;
        let reward = if Some(q) == self.trap {
            trap_reward(q, trap_penalty)?
        } else {
            reading.reward(q, c_r)
        };
        let next = reading.step(q);
        reading.safe_set(next, safe);
        Ok((next, reward))
    }

    /// The CBF safe set of Eq. 5C1 at `(s, q)` ([`Reading::safe_set`]), checked.
    pub fn safe_set(&self, q: usize, s: &[f64]) -> Result<Vec<(Literal, f64)>, AutomatonError> {
        self.check_state("q", q as i64)?;
        let mut out = Vec::with_capacity(self.trap_cnf[q].len());
        self.read(s)?.safe_set(q, &mut out);
        Ok(out)
    }

    /// The CLF goal of Eq. 5B1 at `(s, q)` ([`Reading::goal`]), checked; `None` without one.
    pub fn goal(&self, q: usize, s: &[f64]) -> Result<Option<Vec<f64>>, AutomatonError> {
        self.check_state("q", q as i64)?;
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

/// The cube of a DNF with the largest robustness (the first on ties) and that robustness.
fn best_cube<'a>(guard: &'a [Cube], rho: &[f64]) -> Option<(&'a Cube, f64)> {
    guard
        .iter()
        .map(|c| (c, c.robustness(rho)))
        .fold(None, first_max)
}
