"""A batch row's cost on 1, 2 and all threads: ``Shield.filter_batch`` and
``Shield.jacobian_batch`` (action gradients only, and with the state gradients) per row, on
``compare_shield.py``'s random steps of the paper's task, optionally against another build in
the same run (B A B A).

Each thread count runs in its own process (the pool's size is fixed when it starts:
``RAYON_NUM_THREADS``). With ``--against DIR`` (the ``python/`` folder of another checkout, its
``_core`` built), the two builds take turns: HEAD, the other, HEAD, the other; each figure is the
median of its build's turns, so a slow phase of a shared machine hits both alike.

Targets (issue "the batch path at one step's cost"): on one thread, ``filter_batch`` and
``jacobian_batch`` at most 2.5 us per row; the Jacobian at most 1.3x the filter; 2 threads at
least 1.7x one thread for both.

Run: ``.venv/bin/python benches/batch_rows.py [--quick] [--rows 1024,16384] [--against DIR]``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
TARGET_PER_ROW_US = 2.5
TARGET_JACOBIAN = 1.3
TARGET_TWO_THREADS = 1.7
#: The calls timed, in the table's order.
CALLS = ("filter_batch", "jacobian_batch (actions)", "jacobian_batch (states)")


def worker(rows: list[int], budget: float, seed: int) -> dict[str, dict[str, float]]:
    """Seconds per row of each call at each batch size, in this process (its thread count)."""
    sys.path.insert(0, str(HERE))
    from compare_robustness import measure
    from compare_shield import make_shield, make_steps

    try:  # the Eq. 5D2 QP as the baselines pose it; builds before routing have no `route`
        shield = make_shield()
    except TypeError:
        shield = make_shield(route=None)
    aut = shield.automaton
    out: dict[str, dict[str, float]] = {}
    for n in rows:
        steps = make_steps(np.random.default_rng(seed), n)
        states = np.stack([s for s, _ in steps])
        actions = np.stack([a for _, a in steps])
        qs = aut.step_batch(states, np.full(n, aut.initial))
        # The Jacobian's actions are the filter's (checked, so that both time the same work).
        action = shield.filter_batch(states, qs, actions).action
        jac = shield.jacobian_batch(states, qs, actions)
        if not np.array_equal(jac[0], action):
            raise AssertionError("jacobian_batch's actions differ from filter_batch's")
        rows_ = (states, qs, actions)
        calls = {
            CALLS[0]: lambda _, r=rows_: shield.filter_batch(*r),
            CALLS[1]: lambda _, r=rows_: shield.jacobian_batch(*r, state_grad=False),
            CALLS[2]: lambda _, r=rows_: shield.jacobian_batch(*r, state_grad=True),
        }
        out[str(n)] = {
            name: measure(call, [None], budget, 5)[0] / n for name, call in calls.items()
        }
    return out


def run_worker(
    python_dir: Path, threads: int, rows: list[int], budget: float, seed: int
) -> dict[str, dict[str, float]]:
    env = dict(os.environ, PYTHONPATH=str(python_dir), RAYON_NUM_THREADS=str(threads))
    cmd = [sys.executable, __file__, "--worker", "--rows", ",".join(map(str, rows))]
    cmd += ["--budget", str(budget), "--seed", str(seed)]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"worker ({python_dir}, {threads} threads) failed:\n{done.stderr}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a short budget (smoke run)")
    parser.add_argument("--rows", default="1024,16384", help="batch sizes, comma-separated")
    parser.add_argument("--against", type=Path, help="another build's python/ folder")
    parser.add_argument("--rounds", type=int, default=2, help="turns per build")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--budget", type=float, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    rows = [int(r) for r in args.rows.split(",")]
    if any(r < 1 for r in rows):
        parser.error("--rows: batch sizes must be positive")
    budget = args.budget if args.budget is not None else (0.2 if args.quick else 1.5)
    if args.worker:
        print(json.dumps(worker(rows, budget, args.seed)))
        return 0

    cores = os.cpu_count() or 1
    thread_counts = sorted({1, min(2, cores), cores})
    builds = {"HEAD": ROOT / "python"}
    if args.against is not None:
        builds["against"] = args.against.resolve()
    rounds = 1 if args.quick else args.rounds
    # samples[build][threads][rows][call] -> list of seconds per row
    samples: dict[str, dict[int, list[dict[str, dict[str, float]]]]] = {
        b: {t: [] for t in thread_counts} for b in builds
    }
    for _ in range(rounds):
        for t in thread_counts:
            for name, path in builds.items():
                samples[name][t].append(run_worker(path, t, rows, budget, args.seed))

    def per_row(build: str, t: int, n: int, call: str) -> float:
        return float(np.median([s[str(n)][call] for s in samples[build][t]]))

    print(f"{cores} cores, {rounds} turn(s) per build, seed {args.seed}; us per row (median)\n")
    verdicts = []
    for name in builds:
        print(f"### {name} ({builds[name]})\n")
        print("| rows | threads | " + " | ".join(CALLS) + " | Jacobian (states) / filter |")
        print("|---:|---:|" + "---:|" * (len(CALLS) + 1))
        for n in rows:
            for t in thread_counts:
                us = [per_row(name, t, n, c) * 1e6 for c in CALLS]
                ratio = us[2] / us[0]
                cells = " | ".join(f"{u:.2f}" for u in us)
                print(f"| {n:,} | {t} | {cells} | {ratio:.2f}x |")
        print()
    print("### Targets (HEAD)\n")
    for n in rows:
        one = [per_row("HEAD", 1, n, c) * 1e6 for c in CALLS]
        for call, u in zip(CALLS, one, strict=True):
            ok = u <= TARGET_PER_ROW_US
            verdicts.append(ok)
            print(
                f"- {n:,} rows, one thread, {call}: {u:.2f} us per row (<= "
                f"{TARGET_PER_ROW_US}: {'ok' if ok else 'NOT MET'})"
            )
        for call, u in zip(CALLS[1:], one[1:], strict=True):
            ok = u / one[0] <= TARGET_JACOBIAN
            verdicts.append(ok)
            print(
                f"- {n:,} rows, {call} / filter_batch: {u / one[0]:.2f}x (<= "
                f"{TARGET_JACOBIAN}: {'ok' if ok else 'NOT MET'})"
            )
        if 2 in thread_counts:
            for call in CALLS:
                gain = per_row("HEAD", 1, n, call) / per_row("HEAD", 2, n, call)
                ok = gain >= TARGET_TWO_THREADS
                verdicts.append(ok)
                print(
                    f"- {n:,} rows, {call}, 2 threads vs 1: {gain:.2f}x (>= "
                    f"{TARGET_TWO_THREADS}: {'ok' if ok else 'NOT MET'})"
                )
    if "against" in builds:
        print("\n### HEAD against the other build (its time / HEAD's, > 1: HEAD faster)\n")
        print("| rows | threads | " + " | ".join(CALLS) + " |")
        print("|---:|---:|" + "---:|" * len(CALLS))
        for n in rows:
            for t in thread_counts:
                r = [per_row("against", t, n, c) / per_row("HEAD", t, n, c) for c in CALLS]
                print(f"| {n:,} | {t} | " + " | ".join(f"{x:.2f}x" for x in r) + " |")
    print(f"\n{sum(verdicts)} of {len(verdicts)} targets met")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
