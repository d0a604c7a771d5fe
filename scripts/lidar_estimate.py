"""How far what the lidar is read to say (``tlshield.envs.safety_gym.lidar``) is from MuJoCo's
true positions, over random rollouts of Safety-Gymnasium's Goal tasks.

MuJoCo's positions are read here only to measure the estimate. Per task and object kind, by
the object's true distance from the agent's body origin (bands up to the lidar's range):

- ``goal``: the goal lidar's :func:`~tlshield.envs.safety_gym.lidar.nearest` against the goal's
  true centre (m);
- ``hazards``, ``vases``: for every object within range, ``true distance - floor`` of its bin
  (how far beyond the floor it lies; never negative if the floors hold) and ``true distance -
  distance to its bin's cover disc`` (the barrier's conservatism at the lidar's origin; never
  negative if the cover holds), and for every clean bin the distance from its exact reading to
  the nearest true centre;
- ``hazards``, ``vases``: the shield's own obstacle points (``sensing="lidar"``,
  :mod:`~tlshield.envs.safety_gym.sensing`): ``point margin``, the object's true clearance
  less what its bin's point's barrier reads, at the reading and at its least from anywhere
  within the step's bound on the robot's motion (``within delta``; never negative if the
  bound holds): what the barrier gives up for what the lidar cannot see.

Each cell is ``median / p99 / max`` over the samples, and ``min`` for the margins (a negative
one would be a bound broken). ``python scripts/lidar_estimate.py --episodes 10 --steps 200``;
the actions are uniform over the policy's box, seeded.
"""

from __future__ import annotations

import argparse
import itertools
from collections import defaultdict

import numpy as np

from tlshield.envs.safety_gym import SafetyGoalEnv
from tlshield.envs.safety_gym import lidar as L

TASKS = ("SafetyPointGoal1-v0", "SafetyPointGoal2-v0", "SafetyCarGoal1-v0")
BANDS = (0.0, 0.5, 1.0, 2.0, 3.0)


def _ego(env: SafetyGoalEnv, names: list[str]) -> np.ndarray:
    """The named bodies' centres in the agent body's frame (planar), as the lidar reads them."""
    data = env._env.task.data
    body = data.body("agent")
    rot = body.xmat.reshape(3, 3)
    out = [(rot.T @ (np.array([*data.body(n).xpos[:2], 0.0]) - body.xpos))[:2] for n in names]
    return np.array(out).reshape(-1, 2)


def _band(d: float) -> str:
    for lo, hi in itertools.pairwise(BANDS):
        if lo <= d < hi:
            return f"{lo:g}-{hi:g} m"
    return "beyond"


def measure(task: str, episodes: int, steps: int, seed: int) -> dict[tuple[str, str, str], list]:
    """Samples per (kind, measure, band)."""
    env = SafetyGoalEnv(task, config="rl", sensing="lidar")
    sensing = env._sensing
    assert sensing is not None
    ring = np.exp(1j * np.linspace(0.0, 2.0 * np.pi, 64, endpoint=False))
    ring2 = np.column_stack([ring.real, ring.imag])
    rng = np.random.default_rng(seed)
    sg = env._env.task
    kinds = {"hazards": sg.hazards.num, "vases": sg.vases.num}
    out: dict[tuple[str, str, str], list] = defaultdict(list)
    try:
        for episode in range(episodes):
            obs, _ = env.reset(seed=seed + episode)
            for _ in range(steps):
                obs, *_, info = env.step(rng.uniform(env.action_space.low, env.action_space.high))
                points = info["state"][env.robot.agent_dim + 2 :].reshape(-1, 2)
                moved = np.vstack([[0.0, 0.0], sensing.delta * ring2])
                goal = _ego(env, ["goal"])[0]
                found = L.nearest(env.lidar(obs, "goal"))
                d = float(np.hypot(*goal))
                if found is not None:
                    got = found[0] * np.array([np.cos(found[1]), np.sin(found[1])])
                    out["goal", "position error", _band(d)].append(np.linalg.norm(got - goal))
                for kind, count in kinds.items():
                    bins = env.lidar(obs, kind)
                    centres = _ego(env, [f"{kind[:-1]}{i}" for i in range(count)])
                    floors = L.floors(bins)
                    discs, radii = L.cover(bins)
                    for c in centres:
                        d = float(np.hypot(*c))
                        if d >= L.MAX_DIST:
                            continue
                        b = int((np.arctan2(c[1], c[0]) % (2 * np.pi)) / (2 * np.pi / L.BINS))
                        b %= L.BINS
                        out[kind, "beyond floor", _band(d)].append(d - floors[b])
                        disc = max(0.0, float(np.hypot(*discs[b])) - radii[b])
                        out[kind, "beyond cover", _band(d)].append(d - disc)
                        if kind in sensing.radii:
                            radius, shared = sensing.radii[kind], sensing.shared
                            true = np.hypot(*(c - moved).T) - radius
                            barrier = np.hypot(*(points[b] - moved).T) - shared
                            out[kind, "point margin", _band(d)].append(true[0] - barrier[0])
                            least = float(np.min(true - barrier))
                            out[kind, "point margin within delta", _band(d)].append(least)
                    for b in range(L.BINS):
                        if L.clean(bins, b) and len(centres):
                            ang = (b + bins[(b + 1) % L.BINS] / bins[b]) * (2 * np.pi / L.BINS)
                            got = L.MAX_DIST * (1 - bins[b]) * np.array([np.cos(ang), np.sin(ang)])
                            err = float(np.min(np.linalg.norm(centres - got, axis=1)))
                            out[kind, "clean bin error", _band(float(np.hypot(*got)))].append(err)
    finally:
        env.close()
    return out


def main(argv: list[str] | None = None) -> None:
    """Prints one table per task (``--help``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--tasks", nargs="+", default=list(TASKS))
    args = parser.parse_args(argv)
    for task in args.tasks:
        samples = measure(task, args.episodes, args.steps, args.seed)
        print(f"**{task}**, {args.episodes} episodes x {args.steps} random steps (m)")
        print()
        print("| object | measure | band | samples | min | median | p99 | max |")
        print("|---|---|---|---:|---:|---:|---:|---:|")
        for (kind, what, band), xs in sorted(samples.items()):
            x = np.asarray(xs)
            q50, q99 = np.quantile(x, [0.5, 0.99])
            print(
                f"| {kind} | {what} | {band} | {len(x)} | {x.min():.2g} | {q50:.3g} "
                f"| {q99:.3g} | {x.max():.3g} |"
            )
        print()


if __name__ == "__main__":
    main()
