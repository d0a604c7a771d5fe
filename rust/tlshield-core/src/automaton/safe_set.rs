//! The CBF safe set of Eq. 5C1 (and the progress-preserving one beyond the paper): per
//! clause of the CNF an automaton state must keep, the literal that holds with the largest
//! margin; a query on a [`Reading`], and the checked [`Automaton::safe_set`].

use super::{Automaton, Reading};
use crate::cnf::Literal;
use crate::error::AutomatonError;

impl Reading<'_> {
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

    /// Per clause, the literal with the largest robustness (the first on ties) into `out`,
    /// each literal once.
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
}

impl Automaton {
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
}

/// Fold step keeping the first item with the largest score: `iter.fold(None, first_max)`.
/// Ties keep the earlier item, so choices are deterministic.
fn first_max<T>(best: Option<(T, f64)>, cur: (T, f64)) -> Option<(T, f64)> {
    match best {
        Some(b) if b.1 >= cur.1 => Some(b),
        _ => Some(cur),
    }
}
