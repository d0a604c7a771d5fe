//! Robustness of the paper's task over T = 200 trajectories: one at a time and a batch of 1000.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;
use tlshield_bench::{random_trajectories, task_spec, STATE_DIM};
use tlshield_core::{Scratch, Trajectory, TrajectoryBatch};

const STEPS: usize = 201;

fn robustness(c: &mut Criterion) {
    let spec = task_spec();
    let one = random_trajectories(1, STEPS, 1);
    let batch = random_trajectories(1000, STEPS, 2);

    let mut group = c.benchmark_group("robustness");
    group.throughput(Throughput::Elements(1));
    group.bench_function("task_T200_single", |b| {
        let mut scratch = Scratch::default();
        b.iter(|| {
            let traj = Trajectory::new(black_box(&one), STATE_DIM).unwrap();
            spec.robustness_with(traj, &mut scratch).unwrap()
        })
    });
    group.throughput(Throughput::Elements(1000));
    group.bench_function("task_T200_batch1000", |b| {
        b.iter(|| {
            let trajs = TrajectoryBatch::new(black_box(&batch), 1000, STEPS, STATE_DIM).unwrap();
            spec.robustness_batch(trajs).unwrap()
        })
    });
    group.bench_function("task_T200_loop1000", |b| {
        let mut scratch = Scratch::default();
        b.iter(|| {
            batch
                .chunks(STEPS * STATE_DIM)
                .map(|t| {
                    let traj = Trajectory::new(black_box(t), STATE_DIM).unwrap();
                    spec.robustness_with(traj, &mut scratch).unwrap()
                })
                .sum::<f64>()
        })
    });
    group.finish();
}

criterion_group!(benches, robustness);
criterion_main!(benches);
