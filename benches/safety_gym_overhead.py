"""The shield's overhead on Safety-Gymnasium: one step of Safety-Gymnasium's own env against one
step of ``tlshield/SafetyPointGoal1-v0`` with the shield (``rl_cbf_clf``: reading the
privileged state, the task monitor, the QP and the info), on the same seeds and actions.

Rounds alternate A B A B (each a fresh episode of ``--steps`` steps from the same seed, the
same random actions); the figure is the median over rounds of the ratio of their mean step
times, so drifts of a shared machine cancel. Target: overhead <= 10 % of Safety-Gymnasium's
own step. ``make safety-gym`` installs the stack.

Run: ``.venv/bin/python benches/safety_gym_overhead.py [--rounds 7] [--steps 1000]``. Exit 2
when the target is missed.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings

import numpy as np

TARGET = 0.10


def step_time(env: object, actions: np.ndarray, seed: int) -> float:
    """Mean seconds per step over one episode of ``actions``."""
    env.reset(seed=seed)  # type: ignore[attr-defined]
    start = time.perf_counter()
    for a in actions:
        out = env.step(a)  # type: ignore[attr-defined]
        if out[-3] or out[-2]:  # terminated or truncated (both APIs end with them and info)
            break
    return (time.perf_counter() - start) / len(actions)


def main() -> int:
    warnings.filterwarnings("ignore", category=RuntimeWarning)  # gymnasium's Box casts
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--steps", type=int, default=1000)
    args = parser.parse_args()
    from tlshield.envs.safety_gym import SafetyGoalEnv, make_builder

    raw = make_builder("SafetyPointGoal1-v0")
    shielded = SafetyGoalEnv("SafetyPointGoal1-v0", "rl_cbf_clf")
    actions = np.random.default_rng(0).uniform(-1, 1, (args.steps, 2))
    ratios, base, ours = [], [], []
    for r in range(args.rounds):
        a = step_time(raw, actions, seed=r)
        b = step_time(shielded, actions, seed=r)
        base.append(a)
        ours.append(b)
        ratios.append(b / a - 1.0)
    overhead = statistics.median(ratios)
    print("| env step | median us / step |")
    print("|---|---:|")
    print(f"| Safety-Gymnasium's own (Builder) | {1e6 * statistics.median(base):.0f} |")
    print(f"| tlshield/SafetyPointGoal1-v0, rl_cbf_clf | {1e6 * statistics.median(ours):.0f} |")
    print(
        f"\nshield overhead: {100 * overhead:.1f} % of Safety-Gymnasium's step "
        f"(median of {args.rounds} paired rounds; target <= {100 * TARGET:.0f} %)"
    )
    return 0 if overhead <= TARGET else 2


if __name__ == "__main__":
    sys.exit(main())
