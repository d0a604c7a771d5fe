//! Boolean functions over atom valuations: minimised DNF (prime implicants, essential primes
//! first, then a deterministic greedy cover), CNF of a complement by De Morgan, their
//! robustness, and the safe-set literal choice of Eq. 5C1.
//!
//! A valuation is a bitmask: bit `i` set means atom `i` holds.

use std::fmt::Write;

/// A conjunction of literals: atom `i` occurs iff bit `i` of `care` is set, positively iff bit
/// `i` of `value` is also set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Cube {
    /// Which atoms occur.
    pub care: u32,
    /// Their polarity (only bits inside `care` are meaningful; others are zero).
    pub value: u32,
}

/// An atom, positive or negated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Literal {
    /// Atom index.
    pub atom: usize,
    /// `false` for a negated atom.
    pub positive: bool,
}

impl Literal {
    /// Robustness of the literal given the atoms' robustness.
    #[inline]
    pub fn robustness(&self, atom_rho: &[f64]) -> f64 {
        if self.positive {
            atom_rho[self.atom]
        } else {
            -atom_rho[self.atom]
        }
    }
}

impl Cube {
    /// Whether the valuation `v` satisfies the cube.
    #[inline]
    pub fn contains(&self, v: u32) -> bool {
        v & self.care == self.value
    }

    /// The literals, in atom order.
    pub fn literals(&self) -> impl Iterator<Item = Literal> + '_ {
        (0..32usize)
            .filter(move |i| self.care >> i & 1 == 1)
            .map(move |i| Literal {
                atom: i,
                positive: self.value >> i & 1 == 1,
            })
    }

    /// Robustness: min over the literals (`+inf` for the empty cube `true`).
    #[inline]
    pub fn robustness(&self, atom_rho: &[f64]) -> f64 {
        let mut rho = f64::INFINITY;
        let mut care = self.care;
        while care != 0 {
            let i = care.trailing_zeros() as usize;
            let r = if self.value >> i & 1 == 1 {
                atom_rho[i]
            } else {
                -atom_rho[i]
            };
            rho = rho.min(r);
            care &= care - 1;
        }
        rho
    }

    /// `a & !b`, or `true` for the empty cube.
    pub fn text(&self, atoms: &[String]) -> String {
        let mut out = String::new();
        for (k, lit) in self.literals().enumerate() {
            if k > 0 {
                out.push_str(" & ");
            }
            if !lit.positive {
                out.push('!');
            }
            out.push_str(&atoms[lit.atom]);
        }
        if out.is_empty() {
            out.push_str("true");
        }
        out
    }
}

/// Robustness of a DNF: max over cubes (`-inf` when empty, i.e. `false`).
pub fn dnf_robustness(cubes: &[Cube], atom_rho: &[f64]) -> f64 {
    cubes
        .iter()
        .map(|c| c.robustness(atom_rho))
        .fold(f64::NEG_INFINITY, f64::max)
}

/// DNF text: cubes joined by ` | ` (`false` when empty).
pub fn dnf_text(cubes: &[Cube], atoms: &[String]) -> String {
    if cubes.is_empty() {
        return "false".into();
    }
    let mut out = String::new();
    for (k, c) in cubes.iter().enumerate() {
        if k > 0 {
            out.push_str(" | ");
        }
        let _ = write!(out, "{}", c.text(atoms));
    }
    out
}

/// A minimised DNF of the function that is true exactly on `minterms` (valuations of
/// `n_atoms` atoms). Deterministic: the same set gives the same cubes in the same order.
pub fn minimise(minterms: &[u32], n_atoms: usize) -> Vec<Cube> {
    let full = if n_atoms == 32 {
        u32::MAX
    } else {
        (1u32 << n_atoms) - 1
    };
    minimise_within(minterms, full)
}

/// [`minimise`] for a function that reads only the atoms in `care`: `minterms` are its
/// valuations restricted to `care` (bits outside are ignored). Gives the same cubes as
/// [`minimise`] on the full cylinder set, with `2^(n - |care|)` times less work.
pub fn minimise_within(minterms: &[u32], care: u32) -> Vec<Cube> {
    minimise_within_until(minterms, care, &|| false).expect("never stopped")
}

/// [`minimise_within`] that asks `stop` between merge levels and cover steps and gives up
/// (`None`) as soon as it says so (a long build the user interrupts).
pub fn minimise_within_until(
    minterms: &[u32],
    care: u32,
    stop: &dyn Fn() -> bool,
) -> Option<Vec<Cube>> {
    let full = care;
    let mut on: Vec<u32> = minterms.iter().map(|v| v & care).collect();
    on.sort_unstable();
    on.dedup();
    if on.is_empty() {
        return Some(Vec::new());
    }
    if on.len() as u64 == 1u64 << care.count_ones() {
        return Some(vec![Cube { care: 0, value: 0 }]);
    }
    // Quine-McCluskey: merge cubes that differ in one cared-for bit until nothing merges.
    // Each level is a sorted, deduplicated vector (partners found by binary search).
    let mut primes: Vec<Cube> = Vec::new();
    let mut level: Vec<Cube> = on
        .iter()
        .map(|&v| Cube {
            care: full,
            value: v,
        })
        .collect();
    let mut merged: Vec<bool> = Vec::new();
    let mut next: Vec<Cube> = Vec::new();
    while !level.is_empty() {
        if stop() {
            return None;
        }
        merged.clear();
        merged.resize(level.len(), false);
        next.clear();
        for (i, c) in level.iter().enumerate() {
            let mut care = c.care & !c.value;
            while care != 0 {
                let bit = care & care.wrapping_neg();
                care &= care - 1;
                let partner = Cube {
                    care: c.care,
                    value: c.value | bit,
                };
                if let Ok(j) = level.binary_search(&partner) {
                    merged[i] = true;
                    merged[j] = true;
                    next.push(Cube {
                        care: c.care & !bit,
                        value: c.value,
                    });
                }
            }
        }
        primes.extend(
            level
                .iter()
                .zip(&merged)
                .filter(|(_, &m)| !m)
                .map(|(c, _)| *c),
        );
        next.sort_unstable();
        next.dedup();
        std::mem::swap(&mut level, &mut next);
    }
    // Fewest literals first, then by literal pattern: the order the cover prefers and prints.
    primes.sort_unstable_by_key(|c| (c.care.count_ones(), c.care, c.value));
    primes.dedup();

    let mut uncovered = on;
    let mut chosen: Vec<Cube> = Vec::new();
    // Essential primes: the only prime covering some minterm.
    for &m in &uncovered {
        let mut covering = primes.iter().filter(|p| p.contains(m));
        if let (Some(p), None) = (covering.next(), covering.next()) {
            if !chosen.contains(p) {
                chosen.push(*p);
            }
        }
    }
    uncovered.retain(|&m| !chosen.iter().any(|c| c.contains(m)));
    // Greedy: the prime covering most of what is left (ties: the earlier prime).
    while !uncovered.is_empty() {
        if stop() {
            return None;
        }
        let best = primes
            .iter()
            .filter(|p| !chosen.contains(p))
            .max_by_key(|p| {
                let count = uncovered.iter().filter(|&&m| p.contains(m)).count();
                (
                    count,
                    std::cmp::Reverse((p.care.count_ones(), p.care, p.value)),
                )
            })
            .copied()
            .expect("the primes cover every minterm");
        chosen.push(best);
        uncovered.retain(|&m| !best.contains(m));
    }
    chosen.sort_unstable_by_key(|c| (c.care.count_ones(), c.care, c.value));
    Some(chosen)
}

/// The CNF of the complement of a DNF (De Morgan): one clause per cube, each the disjunction
/// of the cube's literals negated.
pub fn complement_cnf(cubes: &[Cube]) -> Vec<Vec<Literal>> {
    cubes
        .iter()
        .map(|c| {
            c.literals()
                .map(|l| Literal {
                    atom: l.atom,
                    positive: !l.positive,
                })
                .collect()
        })
        .collect()
}

/// Robustness of a CNF: min over clauses of max over literals (`+inf` when empty).
pub fn cnf_robustness(clauses: &[Vec<Literal>], atom_rho: &[f64]) -> f64 {
    clauses
        .iter()
        .map(|clause| {
            clause
                .iter()
                .map(|l| l.robustness(atom_rho))
                .fold(f64::NEG_INFINITY, f64::max)
        })
        .fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn names(n: usize) -> Vec<String> {
        (0..n).map(|i| format!("x{i}")).collect()
    }

    #[test]
    fn textbook_examples() {
        // a | b over two atoms: minterms 01, 10, 11.
        let cubes = minimise(&[1, 2, 3], 2);
        assert_eq!(dnf_text(&cubes, &names(2)), "x0 | x1");
        // !a & !b.
        assert_eq!(dnf_text(&minimise(&[0], 2), &names(2)), "!x0 & !x1");
        assert_eq!(dnf_text(&minimise(&[], 2), &names(2)), "false");
        assert_eq!(dnf_text(&minimise(&[0, 1, 2, 3], 2), &names(2)), "true");
        // CNF of the complement of (a | b) is !a & !b: clauses {!a}, {!b}.
        let cnf = complement_cnf(&cubes);
        assert_eq!(
            cnf,
            vec![
                vec![Literal {
                    atom: 0,
                    positive: false
                }],
                vec![Literal {
                    atom: 1,
                    positive: false
                }]
            ]
        );
    }

    #[test]
    fn robustness_of_dnf_and_cnf() {
        let rho = [0.5, -2.0];
        let cubes = minimise(&[1, 2, 3], 2);
        assert_eq!(dnf_robustness(&cubes, &rho), 0.5);
        assert_eq!(cnf_robustness(&complement_cnf(&cubes), &rho), -0.5);
    }

    proptest! {
        #![proptest_config(crate::tests_support::seeded(500))]

        #[test]
        fn minimised_dnf_is_exact_and_prime(n in 1usize..6, bits in any::<u64>()) {
            let size = 1u32 << n;
            let on: Vec<u32> = (0..size).filter(|v| bits >> (v % 64) & 1 == 1).collect();
            let cubes = minimise(&on, n);
            for v in 0..size {
                prop_assert_eq!(cubes.iter().any(|c| c.contains(v)), on.contains(&v));
            }
            // Prime: dropping any literal of any cube covers an off-set valuation.
            for c in &cubes {
                for lit in c.literals() {
                    let bit = 1u32 << lit.atom;
                    let wider = Cube { care: c.care & !bit, value: c.value & !bit };
                    prop_assert!((0..size).any(|v| wider.contains(v) && !on.contains(&v)));
                }
            }
            // The complement CNF is true exactly off the set.
            let cnf = complement_cnf(&cubes);
            for v in 0..size {
                let holds = cnf.iter().all(|cl| cl.iter().any(|l| (v >> l.atom & 1 == 1) == l.positive));
                prop_assert_eq!(holds, !on.contains(&v));
            }
            prop_assert_eq!(minimise(&on, n), cubes);
        }
    }
}
