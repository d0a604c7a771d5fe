//! Shared fixtures of the core's tests and benchmarks (feature `fixtures`): the paper's
//! case-study task, written once, and (in tests) random formulas and trajectories.

use crate::automaton::Automaton;
use crate::predicate::{Center, Predicate};
use crate::spec::Spec;

/// The paper's task formula (Sec. VI): visit g1 or g2, then g3, staying in the channel.
pub const TASK: &str = "(F g1 | F g2) & F g3 & (!g3 U (g1 | g2)) & ((c1 & c2) U g3)";

/// State length of the case study: x, y, theta, three goal centres, two obstacle centres.
pub const STATE_DIM: usize = 13;

/// Half-width parameter of the channel walls `+-(x - y) + HALF_WIDTH >= 0`.
pub const HALF_WIDTH: f64 = 1.5;

/// Channel wall `sign * (x - y) + HALF_WIDTH` over the case-study state.
pub fn channel(sign: f64) -> Predicate {
    let mut w = vec![0.0; STATE_DIM];
    w[0] = sign;
    w[1] = -sign;
    Predicate::halfspace(w, HALF_WIDTH).expect("finite weights")
}

/// The task spec: Ball goals (radius 0.5) whose centres are read from the state, declared
/// mutually exclusive (the geometry of moving centres cannot tell), and the two channel walls
/// c1, c2.
pub fn task_spec() -> Spec {
    let goal = |k: usize| {
        Predicate::ball(vec![0, 1], 0.5, Center::Dims(vec![3 + 2 * k, 4 + 2 * k]))
            .expect("valid ball")
    };
    Spec::new(
        TASK,
        [
            ("g1", goal(0)),
            ("g2", goal(1)),
            ("g3", goal(2)),
            ("c1", channel(1.0)),
            ("c2", channel(-1.0)),
        ],
    )
    .and_then(|spec| spec.with_exclusive([["g1", "g2", "g3"]]))
    .expect("the task parses")
}

/// The task's minimal automaton.
pub fn task_automaton() -> Automaton {
    Automaton::build(&task_spec()).expect("the task builds")
}

#[cfg(test)]
pub use random::*;

#[cfg(test)]
mod random {
    use super::*;
    use crate::formula::Formula;
    use proptest::prelude::*;

    /// Atom names of the random formulas (three halfspaces and a ball over a 3-d state).
    pub const NAMES: [&str; 4] = ["p", "q", "r", "ball"];

    /// The predicates of [`NAMES`].
    pub fn predicates() -> Vec<(&'static str, Predicate)> {
        let axis = |k: usize| {
            let mut w = vec![0.0; 3];
            w[k] = 1.0;
            Predicate::halfspace(w, 0.0).unwrap()
        };
        vec![
            ("p", axis(0)),
            ("q", axis(1)),
            ("r", axis(2)),
            (
                "ball",
                Predicate::ball(vec![0, 1], 1.0, Center::Fixed(vec![0.5, -0.5])).unwrap(),
            ),
        ]
    }

    fn propositional(atoms: usize) -> impl Strategy<Value = Formula> {
        let leaf = prop_oneof![
            8 => (0..atoms).prop_map(Formula::Atom),
            1 => Just(Formula::True),
            1 => Just(Formula::False),
        ];
        leaf.prop_recursive(3, 12, 3, |inner| {
            prop_oneof![
                inner.clone().prop_map(|a| Formula::Not(Box::new(a))),
                (inner.clone(), inner.clone()).prop_map(|(a, b)| Formula::and(vec![a, b])),
                (inner.clone(), inner.clone()).prop_map(|(a, b)| Formula::or(vec![a, b])),
                (inner.clone(), inner)
                    .prop_map(|(a, b)| Formula::Implies(Box::new(a), Box::new(b))),
            ]
        })
    }

    /// Random syntactically co-safe formulas over [`NAMES`].
    pub fn co_safe() -> impl Strategy<Value = Formula> {
        co_safe_over(NAMES.len())
    }

    /// Random syntactically co-safe formulas over atoms `0..atoms`.
    pub fn co_safe_over(atoms: usize) -> impl Strategy<Value = Formula> {
        propositional(atoms).prop_recursive(4, 24, 3, move |inner| {
            prop_oneof![
                propositional(atoms).prop_map(|a| Formula::Not(Box::new(a))),
                (inner.clone(), inner.clone()).prop_map(|(a, b)| Formula::and(vec![a, b])),
                (inner.clone(), inner.clone()).prop_map(|(a, b)| Formula::or(vec![a, b])),
                (propositional(atoms), inner.clone())
                    .prop_map(|(a, b)| Formula::Implies(Box::new(a), Box::new(b))),
                (inner.clone(), inner.clone())
                    .prop_map(|(a, b)| Formula::Until(Box::new(a), Box::new(b))),
                inner.clone().prop_map(|a| Formula::Eventually(Box::new(a))),
                inner.prop_map(|a| Formula::Next(Box::new(a))),
            ]
        })
    }

    /// Trajectories on a coarse grid (so ties and exact zeros happen) or continuous values.
    pub fn trajectory() -> impl Strategy<Value = Vec<f64>> {
        let value = prop_oneof![(-2i32..=2).prop_map(|v| v as f64 * 0.5), -2.0..2.0f64];
        (1usize..8).prop_flat_map(move |steps| prop::collection::vec(value.clone(), steps * 3))
    }

    /// A random formula bound to [`predicates`].
    pub fn spec_for(f: &Formula) -> Spec {
        let names: Vec<String> = NAMES.iter().map(|s| s.to_string()).collect();
        Spec::new(&f.display(&names).to_string(), predicates()).unwrap()
    }
}
