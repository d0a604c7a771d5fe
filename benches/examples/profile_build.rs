//! Repeated construction of the task automaton, for profiling (`perf record`).
use tlshield_bench::task_spec;
use tlshield_core::Automaton;

fn main() {
    let spec = task_spec();
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(20_000);
    let start = std::time::Instant::now();
    let mut states = 0;
    for _ in 0..n {
        states += Automaton::build(std::hint::black_box(&spec))
            .unwrap()
            .num_states();
    }
    println!(
        "{:.2} us per build ({states})",
        start.elapsed().as_secs_f64() * 1e6 / n as f64
    );
}
