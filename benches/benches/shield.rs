//! The shield's hot path at the case-study size (m = 2: two channel rows and the safe set,
//! one CLF row, bounds): the bare QP on both solver paths over the same instances, the whole
//! step (predicates, FSA safe set, goal, rows, QP), and the batch calls against the same
//! steps one by one (`shield_batch`, 1,024 rows; throughput in rows, so criterion prints the
//! time per row; `RAYON_NUM_THREADS=1` for one thread).

use std::hint::black_box;
use std::sync::Arc;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use tlshield_bench::{shield_instances, task_shield};
use tlshield_core::active_set::ActiveSetQp;
use tlshield_core::qp::{ClarabelQp, QpSolution, QpStatus};
use tlshield_core::{Automaton, BatchGradient, BatchOutput, SolverChoice, StateBatch};

fn shield(c: &mut Criterion) {
    let automaton = Arc::new(Automaton::build(&tlshield_bench::task_spec()).unwrap());
    let instances = shield_instances(&automaton, 256, 5);
    let auto = task_shield(automaton.clone(), SolverChoice::Auto);
    let problems: Vec<_> = instances
        .iter()
        .map(|(s, q, a)| auto.problem(s, *q, a, None, None).unwrap())
        .filter(|p| p.vars() > 0)
        .collect();

    let mut group = c.benchmark_group("shield_qp");
    let mut k = 0;
    let mut active = ActiveSetQp::new();
    let mut out = QpSolution {
        status: QpStatus::Failed,
        x: Vec::new(),
        z: Vec::new(),
        iterations: 0,
    };
    group.bench_function("active_set", |b| {
        b.iter(|| {
            k += 1;
            active.solve_into(black_box(&problems[k % problems.len()]), &mut out);
            out.status
        })
    });
    let mut clarabel = ClarabelQp::new();
    group.bench_function("clarabel", |b| {
        b.iter(|| {
            k += 1;
            clarabel
                .solve(black_box(&problems[k % problems.len()]))
                .status
        })
    });
    group.finish();

    let mut group = c.benchmark_group("shield_step");
    for (name, choice) in [
        ("auto", SolverChoice::Auto),
        ("active_set", SolverChoice::ActiveSet),
        ("clarabel", SolverChoice::Clarabel),
    ] {
        let sh = task_shield(automaton.clone(), choice);
        group.bench_function(name, |b| {
            b.iter(|| {
                k += 1;
                let (s, q, a) = &instances[k % instances.len()];
                sh.filter(black_box(s), *q, a, None, None).unwrap().status
            })
        });
    }
    group.finish();
}

/// The batch path per row against single steps over the same rows.
fn batch(c: &mut Criterion) {
    const ROWS: usize = 1024;
    let automaton = Arc::new(Automaton::build(&tlshield_bench::task_spec()).unwrap());
    let instances = shield_instances(&automaton, ROWS, 7);
    let sh = task_shield(automaton, SolverChoice::Auto);
    let n = instances[0].0.len();
    let states: Vec<f64> = instances.iter().flat_map(|(s, _, _)| s.clone()).collect();
    let qs: Vec<usize> = instances.iter().map(|(_, q, _)| *q).collect();
    let a_rl: Vec<f64> = instances.iter().flat_map(|(_, _, a)| a.clone()).collect();
    let mut group = c.benchmark_group("shield_batch");
    group.throughput(Throughput::Elements(ROWS as u64));
    group.bench_function("single_steps", |b| {
        b.iter(|| {
            for (s, q, a) in &instances {
                black_box(sh.filter(black_box(s), *q, a, None, None).unwrap().status);
            }
        })
    });
    let mut out = BatchOutput::default();
    group.bench_function("filter_batch", |b| {
        b.iter(|| {
            sh.filter_batch(
                StateBatch::new(black_box(&states), n, &qs),
                &a_rl,
                None,
                &mut out,
            )
            .unwrap()
        })
    });
    let mut grad = BatchGradient::default();
    // With the state gradients `(B, m, n)` and with the action gradients only.
    for (name, want_states) in [
        ("jacobian_batch", true),
        ("jacobian_batch_actions_only", false),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| {
                let states = black_box(&states);
                sh.jacobian_batch(
                    StateBatch::new(states, n, &qs),
                    &a_rl,
                    None,
                    None,
                    want_states,
                    &mut grad,
                )
                .unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, shield, batch);
criterion_main!(benches);
