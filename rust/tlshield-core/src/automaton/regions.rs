//! What the map adds to the automaton (beyond the paper): which letters can occur at all,
//! how far each state is from acceptance over those letters, the goal alternatives of every
//! guard cube, and the progress-preserving safe set's CNF.
//!
//! - A letter (the set of atoms that hold) is *admissible* unless the geometry rules it out:
//!   two of its atoms are regions with no common interior point, or three or more of them
//!   have an empty intersection ([`region`]), or the spec declares two of them exclusive
//!   ([`Spec::with_exclusive`]: moving regions, which the geometry cannot judge). Negated
//!   atoms and half-spaces alone never rule a letter out.
//! - `rank(q)`: fewest transitions from `q` to acceptance over admissible letters (0 at
//!   acceptance, `None` when unreachable, e.g. the trap).
//! - Goal alternatives: a guard cube `a & b & !c` holds where some alternative of its positive
//!   regions (a union is a choice, an intersection needs every part) holds and the negative
//!   literals hold. Geometrically empty alternatives are dropped; each fixed one keeps its
//!   deepest point ([`region::deepest_point`]), the exact goal of Eq. 5B1 for that cube.
//! - The avoid CNF of `q`: the negation of every guard from `q` to a state farther from
//!   acceptance than `q` (or from which it is unreachable), the trap's guard included. For a
//!   formula whose only setback is the trap it equals the trap CNF of Eq. 5C1.

use crate::cnf::{self, Cube, Literal};
use crate::predicate::Predicate;
use crate::region::{self, EMPTY_DEPTH};
use crate::spec::Spec;

use super::Edge;

/// One way a guard cube can hold: the convex leaves of its positive literals' regions.
#[derive(Debug, Clone)]
pub(crate) struct GoalAlternative {
    /// The leaves (balls, half-spaces) that must all hold.
    pub leaves: Vec<Predicate>,
    /// The goal space: the `pos` of the first ball.
    pub dims: Vec<usize>,
    /// The deepest point when every leaf in the goal space is fixed; `None`: it moves, and is
    /// placed at each state.
    pub fixed: Option<Vec<f64>>,
}

/// Per atom pair (row-major, atoms x atoms) whether the two can hold together (`None`: the
/// geometry does not say, as for a formula alone).
pub(super) fn pairs(spec: &Spec) -> Vec<Option<bool>> {
    let n = spec.atoms().len();
    let mut pairs = vec![None; n * n];
    if !spec.is_bound() {
        return pairs;
    }
    let predicates = spec.predicates();
    for i in 0..n {
        for j in i + 1..n {
            let c = region::can_hold_together(&predicates[i], &predicates[j]);
            pairs[i * n + j] = c;
            pairs[j * n + i] = c;
        }
    }
    pairs
}

/// Whether the geometry and the spec's exclusive groups admit the letter `v` (see the module
/// docs); `pairs` from [`pairs`].
pub(super) fn admissible_letter(spec: &Spec, pairs: &[Option<bool>], v: u32) -> bool {
    if spec.exclusive().iter().any(|&g| (v & g).count_ones() > 1) {
        return false;
    }
    if !spec.is_bound() {
        return true;
    }
    let n = spec.atoms().len();
    let atoms: Vec<usize> = (0..n).filter(|i| v >> i & 1 == 1).collect();
    let clash = atoms.iter().enumerate().any(|(k, &i)| {
        atoms[k + 1..]
            .iter()
            .any(|&j| pairs[i * n + j] == Some(false))
    });
    if clash {
        return false;
    }
    // Three or more regions can overlap pairwise with no common point.
    let known: Vec<usize> = atoms
        .iter()
        .copied()
        .filter(|&i| {
            atoms
                .iter()
                .any(|&j| j != i && pairs[i * n + j] == Some(true))
        })
        .collect();
    if known.len() < 3 {
        return true;
    }
    let predicates = spec.predicates();
    let mut joint: Option<Vec<Vec<&Predicate>>> = Some(vec![Vec::new()]);
    for &i in &known {
        joint = match (joint, region::alternatives(&predicates[i])) {
            (Some(acc), Some(alts)) => region::product(&acc, &alts),
            _ => None,
        };
    }
    !matches!(joint, Some(joint) if region::region_nonempty(&joint) == Some(false))
}

/// Fewest transitions from each state to acceptance (`None`: unreachable) along `edges`
/// whose guard has a cube with an admissible letter: `admits(v)` for the cube's positive
/// literals (admissibility is anti-monotone, so that letter is the cube's best witness).
pub fn ranks(
    num_states: usize,
    accepting: &[bool],
    edges: &[Edge],
    admits: impl Fn(u32) -> bool,
) -> Vec<Option<u32>> {
    let usable: Vec<(usize, usize)> = edges
        .iter()
        .filter(|e| e.src != e.dst && e.guard.iter().any(|c| admits(c.value)))
        .map(|e| (e.src, e.dst))
        .collect();
    let mut rank: Vec<Option<u32>> = accepting.iter().map(|&a| a.then_some(0)).collect();
    // Bellman-Ford over at most n rounds: the graph is small (states x edges).
    for _ in 0..num_states {
        let mut changed = false;
        for &(src, dst) in &usable {
            if let Some(r) = rank[dst] {
                if rank[src].is_none_or(|x| r + 1 < x) {
                    rank[src] = Some(r + 1);
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
    }
    rank
}

/// The goal alternatives of one guard cube (see the module docs); empty when no alternative
/// has a ball, or every one is geometrically empty.
pub(super) fn goal_alternatives(spec: &Spec, cube: &Cube) -> Vec<GoalAlternative> {
    if !spec.is_bound() {
        return Vec::new();
    }
    let predicates = spec.predicates();
    let mut joint: Vec<Vec<&Predicate>> = vec![Vec::new()];
    for lit in cube.literals().filter(|l| l.positive) {
        let Some(next) = region::alternatives(&predicates[lit.atom])
            .and_then(|alts| region::product(&joint, &alts))
        else {
            return Vec::new();
        };
        joint = next;
    }
    let mut out = Vec::new();
    for leaves in joint {
        let Some(dims) = region::goal_dims(&leaves) else {
            continue;
        };
        let fixed = match region::pieces(&leaves, dims, None) {
            Some(pieces) => match region::deepest_point(&pieces) {
                Some((_, depth)) if depth <= EMPTY_DEPTH => continue,
                Some((x, _)) => Some(x),
                None => continue,
            },
            None => None,
        };
        out.push(GoalAlternative {
            leaves: leaves.into_iter().cloned().collect(),
            dims: dims.to_vec(),
            fixed,
        });
    }
    out
}

/// The avoid CNF of every state (see the module docs): the trap CNF where `q` cannot reach
/// acceptance, duplicate clauses and literals removed.
pub(super) fn avoid_cnf(
    num_states: usize,
    edges: &[Edge],
    ranks: &[Option<u32>],
    trap_cnf: &[Vec<Vec<Literal>>],
) -> Vec<Vec<Vec<Literal>>> {
    (0..num_states)
        .map(|q| {
            let Some(r) = ranks[q] else {
                return trap_cnf[q].clone();
            };
            let setbacks: Vec<Cube> = edges
                .iter()
                .filter(|e| e.src == q && e.dst != q && ranks[e.dst].is_none_or(|d| d > r))
                .flat_map(|e| e.guard.iter().copied())
                .collect();
            dedup_cnf(cnf::complement_cnf(&setbacks))
        })
        .collect()
}

/// The trap's recovery safe set: the clauses that every state with an edge into the trap keeps
/// (the intersection of their negated trap guards). The trap has no edge out, so without it a
/// shield would stop enforcing anything after one slip (model error, a relaxed step, a start
/// inside a hazard); with it, the barriers every way into the trap was holding keep acting and
/// drive the state back (the CBF condition pushes up wherever `h < 0`). The intersection, not
/// the union: a literal only some predecessor kept (for example "not yet in g3" before g1) is
/// no longer a promise worth keeping once the task has failed, and the union could conflict.
pub(super) fn recovery_cnf(trap_cnf: &[Vec<Vec<Literal>>]) -> Vec<Vec<Literal>> {
    let mut into_trap = trap_cnf.iter().filter(|cnf| !cnf.is_empty());
    let Some(first) = into_trap.next() else {
        return Vec::new();
    };
    let rest: Vec<&Vec<Vec<Literal>>> = into_trap.collect();
    first
        .iter()
        .filter(|clause| rest.iter().all(|cnf| cnf.contains(clause)))
        .cloned()
        .collect()
}

/// Sorted literals per clause, no repeated clause.
pub(super) fn dedup_cnf(clauses: Vec<Vec<Literal>>) -> Vec<Vec<Literal>> {
    let mut out: Vec<Vec<Literal>> = Vec::with_capacity(clauses.len());
    for mut clause in clauses {
        clause.sort();
        clause.dedup();
        if !out.contains(&clause) {
            out.push(clause);
        }
    }
    out
}
