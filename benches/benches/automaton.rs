//! The task automaton: construction, and the per-step FSA work (step + reward + safe set).

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
            let next = aut.step(q, black_box(s)).unwrap();
            let reward = aut.reward(q, s, 1.0, None).unwrap();
            let kept = aut.safe_set(q, s, false).unwrap();
            (next, reward, kept.len())
        })
    });
    group.finish();
}

criterion_group!(benches, automaton);
criterion_main!(benches);
