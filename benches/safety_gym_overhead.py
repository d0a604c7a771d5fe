"""The shield's overhead on Safety-Gymnasium: what ``tlshield/SafetyPointGoal1-v0`` with the
shield (``rl_cbf_clf``: reading the privileged state, or with ``--sensing lidar`` writing the
state from the observation, then the QP, the task monitor and the info) adds to
Safety-Gymnasium's own step.

Each round is a fresh episode of ``--steps`` random actions. Within it, the time spent inside
Safety-Gymnasium's ``step`` is timed apart from the whole shielded step, so both are measured
on the same steps (the shield changes the actions, and with them the physics: a second env on
the same actions would not step the same states). The figure is the median over rounds of
``(whole - inside) / inside``. For context, rounds of Safety-Gymnasium's own env on the same
actions alternate with them. Target: overhead <= 10 % of Safety-Gymnasium's own step.
``make safety-gym`` installs the stack.

Run: ``.venv/bin/python benches/safety_gym_overhead.py [--rounds 7] [--steps 1000]
[--task SafetyCarGoal1-v0] [--sensing lidar]``. Exit 2 when the target is missed.
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
    parser.add_argument(
        "--task", default="SafetyPointGoal1-v0", help="one of tlshield.envs.safety_gym.TASKS"
    )
    parser.add_argument("--sensing", default="state", help="what the shield reads: state, lidar")
    args = parser.parse_args()
    from tlshield.envs.safety_gym import SafetyGoalEnv, make_builder

    raw = make_builder(args.task)
    shielded = SafetyGoalEnv(args.task, "rl_cbf_clf", actions="native", sensing=args.sensing)
    actions = np.random.default_rng(0).uniform(-1, 1, (args.steps, 2))
    inner = {"seconds": 0.0, "steps": 0}
    step = shielded._env.step

    def timed(action: np.ndarray) -> tuple:
        start = time.perf_counter()
        out = step(action)
        inner["seconds"] += time.perf_counter() - start
        inner["steps"] += 1
        return out

    shielded._env.step = timed
    ratios, base, ours, inside = [], [], [], []
    for r in range(args.rounds):
        base.append(step_time(raw, actions, seed=r))
        inner["seconds"], inner["steps"] = 0.0, 0
        ours.append(step_time(shielded, actions, seed=r))
        inside.append(inner["seconds"] / args.steps)
        ratios.append(ours[-1] / inside[-1] - 1.0)
    overhead = statistics.median(ratios)
    print("| env step | median us / step |")
    print("|---|---:|")
    rows = [
        ("Safety-Gymnasium's own (Builder), random actions", base),
        (f"tlshield/{args.task}, rl_cbf_clf, sensing={args.sensing}: whole step", ours),
        ("of which inside Safety-Gymnasium's step", inside),
    ]
    for name, times in rows:
        print(f"| {name} | {1e6 * statistics.median(times):.0f} |")
    print(
        f"\nshield overhead: {100 * overhead:.1f} % of Safety-Gymnasium's step "
        f"(median of {args.rounds} rounds; target <= {100 * TARGET:.0f} %)"
    )
    return 0 if overhead <= TARGET else 2


if __name__ == "__main__":
    sys.exit(main())
