"""The moving-obstacle barrier under attack: adversarial policies on Channel-v0 with the CBF.

Half of the episodes drive at full speed at the nearer obstacle, half at the nearer channel
wall, each with random bursts. The shield sees each obstacle as a barrier ``|p - o| >= r_b``
whose centre moves with the velocity the environment measured from its last two positions.
Reports collisions (``d < obstacle_radius``), the minimum distance, channel violations, and
how often the QP was infeasible (channel and obstacle together) with what the shield did.

    .venv/bin/python benches/moving_obstacles.py [--steps 100000] [--seed 0]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from tlshield.codes import Status
from tlshield.envs.channel import ChannelEnv
from tlshield.envs.layout import OBSTACLE_DIMS, THETA, X, Y


def towards(env: ChannelEnv, target: np.ndarray) -> np.ndarray:
    """The normalised action that drives the reference point straight at ``target``."""
    s = env.state
    d = target - s[X : Y + 1]
    v = d / max(float(np.linalg.norm(d)), 1e-9) * 2.0
    th, eps = s[THETA], env.params.agent.eps
    a = np.array(
        [
            math.cos(th) * v[0] + math.sin(th) * v[1],
            (-math.sin(th) * v[0] + math.cos(th) * v[1]) / eps,
        ]
    )
    lo, hi = (np.asarray(b) for b in env.params.agent.rl_bounds)
    return np.clip((a - (hi + lo) / 2) / ((hi - lo) / 2), -1.0, 1.0)


def attack(steps: int, seed: int, config: str, **overrides: object) -> dict[str, float]:
    env = ChannelEnv(config=config, **overrides)
    rng = np.random.default_rng(seed)
    episode = 0
    env.reset(seed=seed * 100_000 + episode)
    counts = {"collisions": 0, "violations": 0, "relaxed": 0, "failed": 0, "steps": 0}
    min_d, min_h, max_slack = math.inf, math.inf, 0.0
    at_obstacle = True
    for _ in range(steps):
        s = env.state
        p = s[X : Y + 1]
        obstacles = [s[a : b + 1] for a, b in OBSTACLE_DIMS]
        if at_obstacle:
            target = min(obstacles, key=lambda o: float(np.linalg.norm(o - p)))
        else:  # the nearer wall: straight across the channel
            side = 1.0 if p[1] - p[0] > 0 else -1.0
            target = p + np.array([-side, side]) * 5.0
        action = towards(env, target)
        if rng.random() < 0.2:
            action = rng.uniform(-1, 1, size=2)
        _, _, terminated, truncated, info = env.step(action)
        counts["steps"] += 1
        counts["collisions"] += info["collision"]
        counts["violations"] += info["violation"]
        status = info["shield"]["status"]
        counts["relaxed"] += status == Status.RELAXED
        counts["failed"] += status == Status.FAILED
        min_d = min(min_d, info["min_obstacle_distance"])
        min_h = min(min_h, *info["constraints"].values())
        if status == Status.RELAXED:
            max_slack = max(max_slack, env.last_slack)
        if terminated or truncated:
            episode += 1
            at_obstacle = episode % 2 == 0
            env.reset(seed=seed * 100_000 + episode)
    return {**counts, "min_distance": min_d, "min_h": min_h, "max_slack": max_slack}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(
        f"{'setting':<44} {'steps':>7} {'coll':>5} {'min d':>6} {'viol':>5} "
        f"{'min h':>7} {'relaxed':>7} {'failed':>6} {'max slack':>9}"
    )
    for label, overrides in (
        ("rl_cbf, moving-obstacle barrier (default)", {}),
        ("rl_cbf, barrier without drift (static)", {"obstacle_drift": False}),
        ("rl_cbf, no obstacle barrier (paper)", {"obstacle_barrier": False}),
    ):
        start = time.perf_counter()
        r = attack(args.steps, args.seed, "rl_cbf", **overrides)
        print(
            f"{label:<44} {r['steps']:>7} {r['collisions']:>5} {r['min_distance']:>6.3f} "
            f"{r['violations']:>5} {r['min_h']:>7.4f} {r['relaxed']:>7} {r['failed']:>6} "
            f"{r['max_slack']:>9.3g}  ({time.perf_counter() - start:.0f} s)",
            flush=True,
        )


if __name__ == "__main__":
    main()
