"""What routing costs where it has work to do: the shield step with the CLF's target routed
around eight discs (the ``random8`` layout of ``tlshield.lab.routing``, obstacles as barriers),
against the same shield with ``route=False``, on the same states, in one run.

States are drawn in the arena outside the discs, with the goal behind them, so that most steps
plan a path (the compare_shield.py steps rarely do: their obstacles are far away). Reports the
median step and its p99 for both, and the ratios.

Run: ``.venv/bin/python benches/compare_routing.py [--quick]``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from compare_shield import step_percentiles

#: Routing may cost at most this many times the unrouted step (median) on these steps.
TARGET_ROUTED = 2.0
#: p99 at most this many times the median.
TARGET_TAIL = 3.0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer passes (smoke run)")
    parser.add_argument("--steps", type=int, default=500)
    args = parser.parse_args(argv)
    from tlshield.lab import routing

    rng = np.random.default_rng(0)
    obstacles = routing.layout("random8", rng)
    goal = routing.GOAL
    shields = {
        on: routing.shield_for("single", obstacles, goal, "barriers", route=on)
        for on in (False, True)
    }
    q = shields[True].automaton.initial
    states = []
    while len(states) < args.steps:
        p = rng.uniform([-2.2, -1.6], [1.0, 1.6])
        if all(np.linalg.norm(p - c) > r * 1.05 for c, r in obstacles):
            states.append((p, rng.uniform(-0.5, 0.5, 2)))
    routed = sum(not np.array_equal(shields[True].filter(s, q, a).goal, goal) for s, a in states)
    passes = 5 if args.quick else 31
    tails = {
        on: step_percentiles(lambda item, sh=sh: sh.filter(item[0], q, item[1]), states, passes)
        for on, sh in shields.items()
    }
    ratio = tails[True]["p50"] / tails[False]["p50"]
    tail = tails[True]["p99"] / tails[True]["p50"]
    print(
        f"{len(states)} steps among 8 discs, {routed} of them routed (the target is not the goal)"
    )
    for on, t in tails.items():
        print(
            f"  route={on}: p50 {t['p50'] * 1e6:.2f} us, p99 {t['p99'] * 1e6:.2f} us, "
            f"max {t['max'] * 1e6:.2f} us"
        )
    ok = ratio <= TARGET_ROUTED, tail <= TARGET_TAIL
    print(
        f"routed / unrouted median: {ratio:.2f}x (target <= {TARGET_ROUTED:g}x, "
        f"{'ok' if ok[0] else 'ABOVE TARGET'}); routed p99 / p50: {tail:.2f} (target <= "
        f"{TARGET_TAIL:g}, {'ok' if ok[1] else 'ABOVE TARGET'})"
    )
    return 0 if all(ok) else 2


if __name__ == "__main__":
    raise SystemExit(main())
