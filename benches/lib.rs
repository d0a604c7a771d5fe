//! Shared fixtures for the criterion benchmarks: the paper's case-study task and seeded
//! trajectories (a tiny xorshift generator keeps the benches free of extra dependencies).

use std::sync::Arc;

use tlshield_core::{Automaton, Bounds, Dynamics, Shield, ShieldParams, SolverChoice};

pub use tlshield_core::fixtures::{task_spec, STATE_DIM, TASK};

/// `count` random-walk trajectories of `steps` states each, flattened `(count, steps, 13)`.
pub fn random_trajectories(count: usize, steps: usize, seed: u64) -> Vec<f64> {
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut out = Vec::with_capacity(count * steps * STATE_DIM);
    for _ in 0..count {
        let goals: Vec<f64> = (0..10).map(|_| 4.0 * uniform() - 2.0).collect();
        let (mut x, mut y) = (0.0, 0.0);
        for _ in 0..steps {
            x += 0.2 * (uniform() - 0.5);
            y += 0.2 * (uniform() - 0.5);
            out.extend_from_slice(&[x, y, 0.0]);
            out.extend_from_slice(&goals);
        }
    }
    out
}

/// The case-study shield (unicycle, eps = 0.1; alpha 2, c3 1, K 1e4; CBF box +-6, CLF box
/// +-0.5), as `tests/shield_reference.py` and `benches/compare_shield.py` use it.
pub fn task_shield(automaton: Arc<Automaton>, solver: SolverChoice) -> Shield {
    let bounds = |v: f64| Bounds::new(vec![-v; 2], vec![v; 2]);
    let params = ShieldParams::new(2.0, 1.0, 1e4, bounds(6.0), bounds(0.5)).with_solver(solver);
    let unicycle = Dynamics::unicycle(0.1, 0, 1, 2).unwrap();
    Shield::new(automaton, Some(unicycle), params).unwrap()
}

/// `count` seeded shield steps `(s, q, a_rl)`: the reference point anywhere across the channel
/// (and a little outside), random heading and goals, RL actions over the whole RL range; `q`
/// is the FSA state after reading `s` from the initial state.
pub fn shield_instances(
    automaton: &Automaton,
    count: usize,
    seed: u64,
) -> Vec<(Vec<f64>, usize, Vec<f64>)> {
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut uniform = move |lo: f64, hi: f64| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        lo + (hi - lo) * ((state >> 11) as f64 / (1u64 << 53) as f64)
    };
    (0..count)
        .map(|_| {
            let (along, across) = (uniform(-1.0, 8.0), uniform(-1.6, 1.6));
            let mut s = vec![
                along + across / 2.0,
                along - across / 2.0,
                uniform(-3.2, 3.2),
            ];
            s.extend((0..6).map(|_| uniform(-1.0, 10.0)));
            s.extend([20.0, 20.0, 20.0, -20.0]);
            let q = automaton.read(&s).unwrap().step(automaton.initial());
            (s, q, vec![uniform(-4.0, 4.0), uniform(-6.0, 6.0)])
        })
        .collect()
}
