//! The FSA-augmented reward of Eq. 5A1: the value of being in an automaton state at a state
//! of the plant, a query on a [`Reading`] (the atoms of one state, computed once); the checked
//! [`Automaton::reward`] validates its inputs and reads the state itself.

use smallvec::SmallVec;

use super::{Automaton, Reading};
use crate::cnf;
use crate::error::{AutomatonError, InputError};
use crate::predicate::{Center, Predicate};

/// The default weight `c_r` of Eq. 5A1's trap term (the paper's task reward).
pub const DEFAULT_C_R: f64 = 1.0;
/// The default reward of a step in the trap (the paper's task reward).
pub const DEFAULT_TRAP_PENALTY: f64 = -100.0;

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
}

impl Automaton {
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
}

/// Checks Eq. 5A1's trap weight `c_r`: finite and > 0.
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

/// The reward of a step in the trap: `trap_penalty`, which must be given and finite.
fn trap_reward(q: usize, trap_penalty: Option<f64>) -> Result<f64, AutomatonError> {
    match trap_penalty {
        Some(p) => {
            crate::check::check_finite("trap_penalty", &[p], crate::check::SCALAR)?;
            Ok(p)
        }
        None => Err(AutomatonError::TrapReward(q)),
    }
}
