//! Second-order barriers (HOCBF) under acceleration-level models, through the public API:
//! forward invariance of an obstacle's outside under adversarial accelerations, for the double
//! integrator and the acceleration-driven unicycle. Barriers on a point of the body ahead of
//! the reference point (mixed relative degree) under the heading models.

use std::f64::consts::PI;
use std::sync::Arc;

use tlshield_core::{
    Automaton, Barrier, Bounds, Center, Dynamics, Offset, Predicate, Shield, ShieldParams, Spec,
    Status,
};

/// Adversarial steps per model (the README quotes this run).
const STEPS: usize = 100_000;

/// A small deterministic generator (xorshift), so the test needs no extra crate.
struct Rng(u64);

impl Rng {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        lo + (hi - lo) * ((self.0 >> 11) as f64 / (1u64 << 53) as f64)
    }
}

fn bounds(v: f64, m: usize) -> Bounds {
    Bounds::new(vec![-v; m], vec![v; m])
}

/// A shield keeping `s[0..2]`, or the body point `along` metres ahead of it on the heading
/// `s[2]` (`along > 0`), out of a ball of radius 1 at the origin, CLF off, HOCBF gains 2
/// and 2. The obstacle is a user barrier, or (`in_formula`) an atom of the task `!o U g` whose
/// safe-set literal `!o` the shield enforces.
///
/// `dt`: the shield holds the sampled states (`ShieldParams::dt`) with the default margin;
/// `None`: the continuous-time rows, kept 1 cm clear.
fn shield(model: Dynamics, accel: f64, in_formula: bool, along: f64, dt: Option<f64>) -> Shield {
    let origin = Center::Fixed(vec![0.0, 0.0]);
    let obstacle = match along {
        0.0 => Predicate::ball(vec![0, 1], 1.0, origin).unwrap(),
        _ => {
            let offset = Offset {
                heading: 2,
                along,
                across: 0.0,
            };
            Predicate::body_ball(vec![0, 1], 1.0, origin, offset).unwrap()
        }
    };
    let goal = Predicate::ball(vec![0, 1], 0.2, Center::Fixed(vec![50.0, 50.0])).unwrap();
    let m = model.inputs();
    let params = ShieldParams::new(2.0, 1.0, 1e4, bounds(1e3, m), bounds(0.5, m))
        .with_alpha2(Some(2.0))
        // Kept 1 cm clear in continuous time, so the Euler plant's O(dt^2) error per step
        // cannot carry the state inside; the sampled rows need no such margin.
        .with_margin(dt.map_or(1e-2, |_| ShieldParams::DEFAULT_MARGIN))
        .with_dt(dt)
        .with_parts(true, false)
        .with_action_bounds(Some(bounds(accel, m)));
    let (spec, params) = if in_formula {
        (
            Spec::new("!o U g", [("o", obstacle), ("g", goal)]).unwrap(),
            params,
        )
    } else {
        let barrier = Barrier::outside("o", obstacle);
        (
            Spec::new("F g", [("g", goal)]).unwrap(),
            params.with_barriers(vec![barrier]),
        )
    };
    Shield::new(
        Arc::new(Automaton::build(&spec).unwrap()),
        Some(model),
        params,
    )
    .unwrap()
}

/// The point the barrier protects: `s[0..2]`, or `along` metres ahead on the heading `s[2]`.
fn point(s: &[f64], along: f64) -> (f64, f64) {
    match along {
        0.0 => (s[0], s[1]),
        _ => (s[0] + along * s[2].cos(), s[1] + along * s[2].sin()),
    }
}

/// Steps `steps` adversarial actions (toward the obstacle at full acceleration, or random)
/// from random starts with h >= 0 and psi_1 >= 0, shielded or not, with Euler steps of `dt`;
/// returns (min h, relaxed, failed), h measured at the protected point.
fn attack(
    model: Dynamics,
    start: impl Fn(&mut Rng) -> Vec<f64>,
    (steps, dt): (usize, f64),
    (shielded, in_formula, sampled): (bool, bool, bool),
    along: f64,
) -> (f64, usize, usize) {
    let accel = 2.0;
    let sh = shield(
        model.clone(),
        accel,
        in_formula,
        along,
        sampled.then_some(dt),
    );
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let (mut min_h, mut relaxed, mut failed) = (f64::INFINITY, 0, 0);
    let mut s = start(&mut rng);
    let mut next = vec![0.0; s.len()];
    for t in 0..steps {
        if t % 400 == 0 {
            s = start(&mut rng);
        }
        let m = model.inputs();
        let a_rl: Vec<f64> = if rng.uniform(0.0, 1.0) < 0.7 {
            // Accelerate straight at the obstacle (for the unicycle: full forward, no turn; for
            // a body point, also turning its nose at the obstacle as fast as allowed).
            let (px, py) = (s[0], s[1]);
            let norm = (px * px + py * py).sqrt().max(1e-9);
            match model {
                Dynamics::DoubleIntegrator { .. } => vec![-accel * px / norm, -accel * py / norm],
                _ if along > 0.0 => {
                    let bearing = (-py).atan2(-px) - s[2];
                    vec![accel, accel * bearing.sin().signum()]
                }
                _ => vec![accel, 0.0],
            }
        } else {
            (0..m).map(|_| rng.uniform(-accel, accel)).collect()
        };
        let action = if shielded {
            let q = sh.automaton().initial();
            let out = sh.filter(&s, q, &a_rl, None, None).unwrap();
            match out.status {
                Status::Relaxed | Status::Inaccurate => relaxed += 1,
                Status::Failed => failed += 1,
                Status::Solved => {}
            }
            assert!(out.action.iter().all(|a| a.is_finite()));
            out.action
        } else {
            a_rl
        };
        model.euler_step(&s, &action, dt, &mut next);
        std::mem::swap(&mut s, &mut next);
        let (px, py) = point(&s, along);
        min_h = min_h.min((px * px + py * py).sqrt() - 1.0);
    }
    (min_h, relaxed, failed)
}

/// The attack is real (unshielded, it enters the obstacle), and shielded it never enters,
/// with the obstacle as a user barrier and as an atom of the formula.
fn never_enters(name: &str, model: Dynamics, start: impl Fn(&mut Rng) -> Vec<f64> + Copy) {
    never_enters_at(name, model, start, 0.0);
}

fn never_enters_at(
    name: &str,
    model: Dynamics,
    start: impl Fn(&mut Rng) -> Vec<f64> + Copy,
    along: f64,
) {
    let unshielded = (false, false, false);
    assert!(attack(model.clone(), start, (4_000, 0.01), unshielded, along).0 < 0.0);
    // At the 10 ms of the paper's plant and at 5 ms: exactly outside (min h >= 0), with the
    // continuous-time rows kept 1 cm clear and with the sampled rows at the default margin.
    for dt in [0.01, 0.005, 0.05] {
        for (in_formula, sampled) in [(false, false), (true, false), (false, true), (true, true)] {
            // 50 ms: beyond what 1 cm covers, so the sampled rows only, and not for a body
            // point: its mixed-degree rows stay continuous-time (the bicycle's enters there).
            if dt > 0.01 && (!sampled || along > 0.0) {
                continue;
            }
            let (min_h, relaxed, failed) = attack(
                model.clone(),
                start,
                (STEPS, dt),
                (true, in_formula, sampled),
                along,
            );
            assert!(
                min_h >= 0.0,
                "{name} entered the obstacle at dt {dt} (sampled rows: {sampled}): min h = {min_h}"
            );
            assert_eq!(failed, 0);
            let form = if in_formula {
                "in the formula"
            } else {
                "a user barrier"
            };
            println!(
                "{name}, obstacle {form}, dt {dt}, sampled rows {sampled}, {STEPS} steps: \
                 min h {min_h:.2e}, relaxed {relaxed}, failed {failed}"
            );
        }
    }
}

#[test]
fn double_integrator_never_enters_the_obstacle() {
    let model = Dynamics::double_integrator(vec![0, 1], vec![2, 3]).unwrap();
    // Starts outside, moving at up to 1 m/s, with psi_1 = dh/dt + 2 h >= 0.
    let start = |rng: &mut Rng| loop {
        let angle = rng.uniform(-PI, PI);
        let r = rng.uniform(1.05, 3.0);
        let (px, py) = (r * angle.cos(), r * angle.sin());
        let (vx, vy) = (rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0));
        let psi = (px * vx + py * vy) / r + 2.0 * (r - 1.0);
        if psi >= 0.0 {
            return vec![px, py, vx, vy];
        }
    };
    never_enters("double integrator", model, start);
}

/// A start `[x, y, theta, v]` with the point `along` metres ahead outside the obstacle, driving
/// at up to 1 m/s, with `psi_1 = Lf h + 2 h >= 0` (the unicycle's and the bicycle's state
/// alike: with no input the point moves at `v` along the heading).
fn body_start(rng: &mut Rng, along: f64) -> Vec<f64> {
    loop {
        let angle = rng.uniform(-PI, PI);
        let r = rng.uniform(1.05, 3.0);
        let (qx, qy) = (r * angle.cos(), r * angle.sin());
        let theta = rng.uniform(-PI, PI);
        let v = rng.uniform(0.0, 1.0);
        let psi = v * (qx * theta.cos() + qy * theta.sin()) / r + 2.0 * (r - 1.0);
        if psi >= 0.0 {
            return vec![qx - along * theta.cos(), qy - along * theta.sin(), theta, v];
        }
    }
}

/// [`body_start`] for the reference point itself.
fn heading_start(rng: &mut Rng) -> Vec<f64> {
    body_start(rng, 0.0)
}

/// A point 0.8 m ahead of the reference point (mixed relative degree: the heading is one
/// integration from the turn input, the position two from the acceleration).
#[test]
fn a_body_point_never_enters_the_obstacle() {
    let unicycle = Dynamics::acceleration_unicycle(0, 1, 2, 3).unwrap();
    let bicycle = Dynamics::kinematic_bicycle(0.5, 0, 1, 2, 3).unwrap();
    let models = [
        ("acceleration unicycle, body point", unicycle),
        ("kinematic bicycle, body point", bicycle),
    ];
    for (name, model) in models {
        never_enters_at(name, model, |rng| body_start(rng, 0.8), 0.8);
    }
}

#[test]
fn acceleration_unicycle_never_enters_the_obstacle() {
    let model = Dynamics::acceleration_unicycle(0, 1, 2, 3).unwrap();
    never_enters("acceleration unicycle", model, heading_start);
}

#[test]
fn kinematic_bicycle_never_enters_the_obstacle() {
    // Wheelbase 0.5; the second input is tan(steering), limited to +-2 by the action box.
    let model = Dynamics::kinematic_bicycle(0.5, 0, 1, 2, 3).unwrap();
    never_enters("kinematic bicycle", model, heading_start);
}

#[test]
fn a_second_order_barrier_needs_alpha2() {
    let obstacle = Predicate::ball(vec![0, 1], 1.0, Center::Fixed(vec![0.0, 0.0])).unwrap();
    let spec = Spec::new("F o", [("o", obstacle.clone())]).unwrap();
    let model = Dynamics::double_integrator(vec![0, 1], vec![2, 3]).unwrap();
    let params = ShieldParams::new(2.0, 1.0, 1e4, bounds(5.0, 2), bounds(0.5, 2))
        .with_barriers(vec![Barrier::outside("o", obstacle)]);
    let aut = Arc::new(Automaton::build(&spec).unwrap());
    let err = Shield::new(aut.clone(), Some(model.clone()), params.clone()).unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("relative degree 2") && text.contains("alpha2"),
        "{text}"
    );
    assert!(Shield::new(aut, Some(model), params.with_alpha2(Some(1.0))).is_ok());
}

#[test]
fn a_barrier_no_input_can_reach_is_an_error() {
    // A disc over dimensions 4, 5 (say, another robot's position): the double integrator on
    // 0-3 never moves them, so no CBF of any order can enforce it.
    let other = Predicate::ball(vec![4, 5], 1.0, Center::Fixed(vec![0.0, 0.0])).unwrap();
    let goal = Predicate::ball(vec![0, 1], 0.2, Center::Fixed(vec![5.0, 5.0])).unwrap();
    let spec = Spec::new("F g", [("g", goal)]).unwrap();
    let model = Dynamics::double_integrator(vec![0, 1], vec![2, 3]).unwrap();
    let params = ShieldParams::new(2.0, 1.0, 1e4, bounds(5.0, 2), bounds(0.5, 2))
        .with_alpha2(Some(1.0))
        .with_barriers(vec![Barrier::outside("far", other)]);
    let aut = Arc::new(Automaton::build(&spec).unwrap());
    let text = Shield::new(aut, Some(model), params)
        .unwrap_err()
        .to_string();
    assert!(
        text.contains("\"far\"") && text.contains("relative degree > 2"),
        "{text}"
    );
}
