//! The task automaton: construction, and the per-step FSA work (step + reward + safe set); and
//! a 24-atom sequence `F(a0 & F(a1 & ...))`, built symbolically and stepped through its
//! decision diagrams (issue 24), beside the task's table step.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use tlshield_bench::{random_trajectories, task_spec, STATE_DIM};
use tlshield_core::Automaton;

fn automaton(c: &mut Criterion) {
    let spec = task_spec();
    let mut group = c.benchmark_group("automaton");
    group.bench_function("build_task", |b| {
        b.iter(|| Automaton::build(black_box(&spec)).unwrap())
    });

    let aut = Automaton::build(&spec).unwrap();
    let states = random_trajectories(64, 16, 3);
    let rows: Vec<&[f64]> = states.chunks(STATE_DIM).collect();
    let mut safe = Vec::new();
    let mut k = 0;
    group.bench_function("step_reward_safe_set", |b| {
        b.iter(|| {
            let s = rows[k % rows.len()];
            k += 1;
            let q = if k % 2 == 0 { 0 } else { 3 };
            // The read checks the state (length, finiteness) once and computes the atoms once.
            let reading = aut.read(black_box(s)).unwrap();
            let next = reading.step(q);
            let reward = reading.reward(q, 1.0);
            reading.safe_set(q, &mut safe);
            (next, reward, safe.len())
        })
    });
    group.bench_function("step_reward_safe_set_checked", |b| {
        b.iter(|| {
            let s = rows[k % rows.len()];
            k += 1;
            let q = if k % 2 == 0 { 0 } else { 3 };
            let next = aut.step(black_box(s), q).unwrap();
            let reward = aut.reward(s, q, 1.0, None).unwrap();
            let kept = aut.safe_set(s, q, false).unwrap();
            (next, reward, kept.len())
        })
    });
    // One transition on a precomputed valuation: the task's table lookup, and a walk of the
    // 24-atom sequence's diagrams (no table: 25 states x 2^24 letters).
    let valuations: Vec<usize> = (0..1024usize)
        .map(|i| i.wrapping_mul(2654435761) >> 7)
        .collect();
    let mut i = 0;
    group.bench_function("step_valuation_task_table", |b| {
        b.iter(|| {
            i += 1;
            let v = valuations[i % valuations.len()] & 31;
            aut.step_valuation(black_box(i & 3), v)
        })
    });
    let sequence =
        (1..24).fold("F(a0".to_string(), |f, k| f + &format!(" & F(a{k}")) + &")".repeat(24);
    let sequence = tlshield_core::Spec::from_formula(&sequence).unwrap();
    group.bench_function("build_sequence_24", |b| {
        b.iter(|| Automaton::build(black_box(&sequence)).unwrap())
    });
    let long = Automaton::build(&sequence).unwrap();
    group.bench_function("step_valuation_sequence_24_diagram", |b| {
        b.iter(|| {
            i += 1;
            let v = valuations[i % valuations.len()] & ((1 << 24) - 1);
            long.step_valuation(black_box(i % 25), v)
        })
    });
    group.finish();
}

criterion_group!(benches, automaton);
criterion_main!(benches);
