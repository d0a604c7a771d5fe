//! The router alone among N random discs, for profiling (`perf record`) and for checking that a
//! change keeps its targets: the fields of `benches/route_scaling.py` (discs of radius 0.2 to
//! 0.5, one per 6 m^2, the goal right of them), independent states left of the field and
//! drives through it. Prints, per field, the median, p99 and max of `Router::target` in us,
//! and a checksum of every target's bits (equal checksums: the same targets).
//!
//! Run: `cargo run --release -p tlshield-bench --example route_profile [passes] [N ...]`.
use std::time::Instant;

use tlshield_core::route::{Disc, Router, DEFAULT_CLEARANCE};

/// A small deterministic generator (xorshift64*), so that every build sees the same fields.
struct Rng(u64);

impl Rng {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let bits = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11;
        lo + (hi - lo) * (bits as f64 / (1u64 << 53) as f64)
    }
}

/// `n` non-overlapping discs in a square of half side `1.2 sqrt(n)`, and that half side.
fn field(n: usize, rng: &mut Rng) -> (Vec<Disc>, f64) {
    let side = (1.2 * (n as f64).sqrt()).max(1.0);
    let mut discs: Vec<Disc> = Vec::new();
    while discs.len() < n {
        let center = [rng.uniform(-side, side), rng.uniform(-side, side)];
        let radius = rng.uniform(0.2, 0.5);
        if discs
            .iter()
            .all(|o| (center[0] - o.center[0]).hypot(center[1] - o.center[1]) > radius + o.radius)
        {
            discs.push(Disc { center, radius });
        }
    }
    (discs, side)
}

/// A free point left of the field.
fn start(side: f64, discs: &[Disc], rng: &mut Rng) -> [f64; 2] {
    loop {
        let p = [
            rng.uniform(-side - 1.0, -side + 0.5),
            rng.uniform(-side, side),
        ];
        if discs
            .iter()
            .all(|d| (p[0] - d.center[0]).hypot(p[1] - d.center[1]) > d.radius * 1.05)
        {
            return p;
        }
    }
}

/// Median, p99 and max of `times` (seconds) in us.
fn percentiles(times: &mut [f64]) -> [f64; 3] {
    times.sort_by(f64::total_cmp);
    let at = |q: f64| times[((times.len() - 1) as f64 * q).round() as usize] * 1e6;
    [at(0.5), at(0.99), at(1.0)]
}

/// Times `target` on every `(p, goal)` of `states` (the per-state minimum over `passes`, in
/// order), and folds every target's bits into `sum`.
fn time(
    router: &mut Router,
    states: &[([f64; 2], [f64; 2])],
    passes: usize,
    sum: &mut u64,
) -> [f64; 3] {
    let mut best = vec![f64::INFINITY; states.len()];
    for pass in 0..passes {
        for (k, &(p, goal)) in states.iter().enumerate() {
            let t0 = Instant::now();
            let t = router.target(std::hint::black_box(p), goal, DEFAULT_CLEARANCE);
            best[k] = best[k].min(t0.elapsed().as_secs_f64());
            if pass == 0 {
                for v in t {
                    *sum = sum.rotate_left(5) ^ v.to_bits();
                }
            }
        }
    }
    percentiles(&mut best)
}

fn main() {
    let mut args = std::env::args().skip(1);
    let passes: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(5);
    let mut counts: Vec<usize> = args.filter_map(|a| a.parse().ok()).collect();
    if counts.is_empty() {
        counts = vec![16, 32, 64, 128, 256];
    }
    let mut sum = 0u64;
    for n in counts {
        let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ n as u64);
        let (discs, side) = field(n, &mut rng);
        let goal = [side + 1.0, rng.uniform(-0.5, 0.5) * side];
        let mut router = Router::default();
        for &d in &discs {
            router.push(d);
        }
        let states: Vec<_> = (0..400)
            .map(|_| (start(side, &discs, &mut rng), goal))
            .collect();
        let independent = time(&mut router, &states, passes, &mut sum);
        // Drives: the robot steps 0.05 towards the target each step.
        let mut drive = Vec::new();
        for _ in 0..3 {
            let mut p = start(side, &discs, &mut rng);
            for _ in 0..400 {
                drive.push((p, goal));
                let t = router.target(p, goal, DEFAULT_CLEARANCE);
                let (dx, dy) = (t[0] - p[0], t[1] - p[1]);
                let len = dx.hypot(dy);
                if len < 0.1 {
                    break;
                }
                p = [p[0] + 0.05 * dx / len, p[1] + 0.05 * dy / len];
            }
        }
        let along = time(&mut router, &drive, passes, &mut sum);
        println!(
            "N={n:4} states {:7.2} / {:7.2} / {:7.2}   drive {:7.2} / {:7.2} / {:7.2}  ({} steps)",
            independent[0],
            independent[1],
            independent[2],
            along[0],
            along[1],
            along[2],
            drive.len()
        );
    }
    println!("checksum {sum:016x}");
}
