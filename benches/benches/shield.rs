//! The shield's hot path at the case-study size (m = 2: two channel rows and the safe set,
//! one CLF row, bounds): the bare QP on both solver paths over the same instances, and the
//! whole step (predicates, FSA safe set, goal, rows, QP).

use std::hint::black_box;
use std::sync::Arc;

use criterion::{criterion_group, criterion_main, Criterion};
use tlshield_bench::{shield_instances, task_shield};
use tlshield_core::active_set::ActiveSetQp;
use tlshield_core::qp::{ClarabelQp, QpSolution, QpStatus};
use tlshield_core::{Automaton, SolverChoice};

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

criterion_group!(benches, shield);
criterion_main!(benches);
