//! Regions and rank-aware guidance on FlatWorld's map (DeepLTL's benchmark): unions of discs,
//! goals inside intersections, geometry-admissible letters, the progress-preserving safe set.

use proptest::prelude::*;
use tlshield_core::cnf::Literal;
use tlshield_core::{Automaton, Center, Predicate, Spec};

const CIRCLES: [((f64, f64), f64, &str); 9] = [
    ((-1.4, 0.55), 0.4, "red"),
    ((-1.1, 1.1), 0.5, "magenta"),
    ((-1.0, -1.2), 0.3, "yellow"),
    ((-1.53, -0.5), 0.32, "orange"),
    ((0.1, 0.0), 0.8, "blue"),
    ((0.5, -1.3), 0.35, "red"),
    ((0.7, 0.7), 0.5, "green"),
    ((1.5, -0.75), 0.4, "green"),
    ((0.8, 0.2), 0.3, "aqua"),
];

fn disc(c: (f64, f64), r: f64) -> Predicate {
    Predicate::ball(vec![0, 1], r, Center::Fixed(vec![c.0, c.1])).unwrap()
}

/// Each colour as a disc or the union of its discs.
fn colours() -> Vec<(String, Predicate)> {
    let mut out: Vec<(String, Vec<Predicate>)> = Vec::new();
    for (c, r, name) in CIRCLES {
        match out.iter_mut().find(|(n, _)| n == name) {
            Some((_, v)) => v.push(disc(c, r)),
            None => out.push((name.to_string(), vec![disc(c, r)])),
        }
    }
    out.into_iter()
        .map(|(n, mut v)| {
            let p = if v.len() == 1 {
                v.pop().unwrap()
            } else {
                Predicate::union(v).unwrap()
            };
            (n, p)
        })
        .collect()
}

fn automaton(formula: &str) -> Automaton {
    Automaton::build(&Spec::new(formula, colours()).unwrap()).unwrap()
}

fn holds(aut: &Automaton, name: &str, s: &[f64]) -> bool {
    let i = aut.spec().atoms().iter().position(|a| a == name).unwrap();
    aut.spec().predicates()[i].value(s) > 0.0
}

/// Runs the automaton along `states` from the initial state.
fn run(aut: &Automaton, states: &[[f64; 2]]) -> usize {
    states
        .iter()
        .fold(aut.initial(), |q, s| aut.step(s, q).unwrap())
}

#[test]
fn formula_2_as_written_goes_to_magenta_after_orange_and_keeps_out_of_red() {
    let aut = automaton("F(orange & (!red U magenta))");
    // Enter orange from outside it.
    let q = run(&aut, &[[-1.9, -0.5], [-1.53, -0.5]]);
    assert_ne!(q, aut.initial());
    let s = [-1.53, -0.5];
    // The goal is inside magenta (the edge back to the start, via red, sets the task back).
    let goal = aut.goal(&s, q).unwrap().expect("a goal");
    assert!(holds(&aut, "magenta", &goal), "{goal:?}");
    assert!(!holds(&aut, "red", &goal) || holds(&aut, "magenta", &goal));
    // The trap-only safe set is empty (red only sets the task back) ...
    assert!(aut.safe_set(&s, q, false).unwrap().is_empty());
    // ... the progress-preserving one keeps !red.
    let kept = aut.safe_set(&s, q, true).unwrap();
    let red = aut.spec().atoms().iter().position(|a| a == "red").unwrap();
    assert!(
        kept.iter().any(|(l, h)| *l
            == Literal {
                atom: red,
                positive: false
            }
            && *h > 0.0),
        "{kept:?}"
    );
    // Ranks: the start is two steps from acceptance, after orange one.
    assert_eq!(aut.ranks()[aut.initial()], Some(2));
    assert_eq!(aut.ranks()[q], Some(1));
}

#[test]
fn conjunction_goals_lie_inside_the_intersection_and_empty_cubes_are_skipped() {
    // The mean of blue's and aqua's centres lies outside aqua; the deepest point is inside both.
    let aut = automaton("F(aqua & blue)");
    let s = [-1.9, 1.9];
    let goal = aut.goal(&s, aut.initial()).unwrap().unwrap();
    assert!(
        holds(&aut, "aqua", &goal) && holds(&aut, "blue", &goal),
        "{goal:?}"
    );
    // green & blue: only the first green disc meets blue; the goal is in that intersection,
    // from anywhere (the second green disc, nearer to some starts, is never the goal).
    let aut = automaton("F(green & blue)");
    for s in [[1.9, -0.75], [-1.9, 1.9], [0.0, -1.9]] {
        let goal = aut.goal(&s, aut.initial()).unwrap().unwrap();
        assert!(
            holds(&aut, "green", &goal) && holds(&aut, "blue", &goal),
            "{s:?}: {goal:?}"
        );
    }
}

#[test]
fn geometry_rules_out_letters_and_unreachable_tasks() {
    // Orange and red are disjoint: F(orange & red) has no path to acceptance.
    let aut = automaton("F(orange & red)");
    assert_eq!(aut.ranks()[aut.initial()], None);
    let atoms = aut.spec().atoms();
    let (o, r) = (
        atoms.iter().position(|a| a == "orange").unwrap(),
        atoms.iter().position(|a| a == "red").unwrap(),
    );
    assert_eq!(aut.can_hold_together(o, r), Some(false));
    // Red (a union) overlaps magenta through its first disc.
    let aut = automaton("F(red & magenta)");
    assert_eq!(aut.ranks()[aut.initial()], Some(1));
    // Green, blue and aqua overlap pairwise and all three together.
    let aut = automaton("F(green & blue & aqua)");
    assert_eq!(aut.ranks()[aut.initial()], Some(1));
}

#[test]
fn trap_only_formulas_keep_the_paper_safe_set() {
    // Formula 4's setbacks all lead to the trap: the avoid CNF is the trap CNF.
    let aut = automaton("((!yellow & !orange) U (green & blue)) & (!green U magenta)");
    for q in 0..aut.num_states() {
        let mut a = aut.avoid_cnf(q).unwrap().to_vec();
        let mut t = aut.trap_cnf(q).unwrap().to_vec();
        a.sort();
        t.sort();
        assert_eq!(a, t, "state {q}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, rng_seed: proptest::test_runner::RngSeed::Fixed(7), ..ProptestConfig::default() })]

    /// A union's robustness is the max of its parts', an intersection's the min; the gradient
    /// matches central differences away from the seams.
    #[test]
    fn union_and_intersection_value_and_gradient(x in -2.0..2.0f64, y in -2.0..2.0f64) {
        let a = disc((-0.5, 0.0), 0.6);
        let b = disc((0.4, 0.2), 0.5);
        let h = Predicate::halfspace(vec![0.3, -1.0], 0.2).unwrap();
        let s = [x, y];
        let union = Predicate::union(vec![a.clone(), b.clone(), h.clone()]).unwrap();
        let inter = Predicate::intersection(vec![a.clone(), b.clone(), h.clone()]).unwrap();
        let parts = [a.value(&s), b.value(&s), h.value(&s)];
        prop_assert_eq!(union.value(&s), parts.iter().copied().fold(f64::NEG_INFINITY, f64::max));
        prop_assert_eq!(inter.value(&s), parts.iter().copied().fold(f64::INFINITY, f64::min));
        let mut sorted = parts;
        sorted.sort_by(f64::total_cmp);
        // Away from the seams (the top two / bottom two parts apart) and the centres.
        prop_assume!(sorted[2] - sorted[1] > 1e-3 && sorted[1] - sorted[0] > 1e-3);
        for p in [&union, &inter] {
            let mut g = [0.0; 2];
            p.gradient_into(&s, &mut g);
            for k in 0..2 {
                let e = 1e-7;
                let mut plus = s;
                let mut minus = s;
                plus[k] += e;
                minus[k] -= e;
                let fd = (p.value(&plus) - p.value(&minus)) / (2.0 * e);
                prop_assert!((g[k] - fd).abs() < 1e-5, "{:?} {} {}", p, g[k], fd);
            }
        }
    }
}
