"""Wall time of ``tlshield reproduce`` on its embedded local Ray against the home-made
``multiprocessing`` pool it replaced, on the same jobs, in one run.

Both run the same (configuration x seed) jobs (:func:`tlshield.lab.training.run_job`: train, then
evaluate) with 2 processes at a time, then write the same figures and results table. The pool
is the old code path (a spawn ``Pool.imap_unordered``, kept here only as the baseline); Ray
starts a local instance inside the call, runs each job as a task in a temporary folder and
unpacks the run into the results folder. Rounds alternate which goes first, so a slow phase of
a shared machine hits both alike. The runs must be identical (metrics without wall times):
else exit 1. Target: Ray's median wall time within 10% of the pool's (else exit 2).

Run: ``.venv/bin/python benches/ray_overhead.py [--updates 100] [--rounds 2] [--quick]``.
"""

from __future__ import annotations

import argparse
import csv
import multiprocessing as mp
import shutil
import tempfile
import time
from collections.abc import Sequence
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

TARGET = 1.10


def run_pool(out: Path, jobs: dict[Path, Any], workers: int) -> None:
    """The pre-Ray ``reproduce``: a spawn pool over the jobs, then the figures and table."""
    from tlshield.lab.plots import plot_all
    from tlshield.lab.report import results_table

    out.mkdir(parents=True)
    with mp.get_context("spawn").Pool(min(workers, len(jobs))) as pool:
        for _ in pool.imap_unordered(_apply, list(jobs.items())):
            pass
    plot_all(out)
    (out / "results.md").write_text(results_table(out) + "\n")


def _apply(item: tuple[Path, Any]) -> Path:
    folder, job = item
    return job(folder)


def jobs_for(out: Path, configs: Sequence[str], seeds: Sequence[int], updates: int, trials: int):
    from tlshield.lab.training import run_job

    return {
        out / f"{c}_s{s}": partial(run_job, c, s, updates, trials, {})
        for c in configs
        for s in seeds
    }


def metrics(run: Path) -> list[dict[str, str]]:
    with (run / "metrics.csv").open() as f:
        return [{k: v for k, v in r.items() if k != "wall_time"} for r in csv.DictReader(f)]


def main(argv: Sequence[str] | None = None) -> int:
    from tlshield.envs.channel import CONFIGS
    from tlshield.lab.training import reproduce

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configs", nargs="+", default=list(CONFIGS))
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    parser.add_argument("--updates", type=int, default=100)
    parser.add_argument("--trials", type=int, default=100)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--quick", action="store_true", help="2 jobs, 2 updates, 1 round")
    args = parser.parse_args(argv)
    if args.quick:
        args.configs, args.seeds, args.updates, args.trials, args.rounds = (
            ["rl_cbf_clf"],
            [0, 1],
            2,
            3,
            1,
        )
    n_jobs = len(args.configs) * len(args.seeds)
    print(
        f"{n_jobs} jobs ({', '.join(args.configs)} x seeds {args.seeds}), {args.updates} updates "
        f"and {args.trials} evaluation trials each, {args.workers} at a time, "
        f"{args.rounds} round(s)"
    )
    times: dict[str, list[float]] = {"pool": [], "ray": []}
    scratch = Path(tempfile.mkdtemp(prefix="ray-overhead-"))
    try:
        for k in range(args.rounds):
            order = ("pool", "ray") if k % 2 == 0 else ("ray", "pool")
            for name in order:
                out = scratch / f"{name}{k}"
                start = time.perf_counter()
                if name == "pool":
                    jobs = jobs_for(out, args.configs, args.seeds, args.updates, args.trials)
                    run_pool(out, jobs, args.workers)
                else:
                    reproduce(
                        out,
                        configs=tuple(args.configs),
                        seeds=tuple(args.seeds),
                        updates=args.updates,
                        trials=args.trials,
                        workers=args.workers,
                        progress=False,
                    )
                times[name].append(time.perf_counter() - start)
                print(f"round {k}: {name:<4} {times[name][-1]:7.1f} s", flush=True)
            for run in sorted((scratch / f"pool{k}").glob("*_s*")):
                if metrics(run) != metrics(scratch / f"ray{k}" / run.name):
                    print(f"FAIL: {run.name} differs between the pool and Ray")
                    return 1
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    pool, ray = float(np.median(times["pool"])), float(np.median(times["ray"]))
    ratio = ray / pool
    print()
    print("| runner | wall time (median) | ratio |")
    print("|---|---:|---:|")
    print(f"| multiprocessing pool (before) | {pool:.1f} s | 1.00 |")
    print(f"| local Ray (tlshield reproduce) | {ray:.1f} s | {ratio:.2f} |")
    print(f"runs identical: yes ({n_jobs} jobs x {args.rounds} round(s))")
    if ratio > TARGET:
        print(f"target missed: Ray / pool = {ratio:.2f} > {TARGET}")
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
