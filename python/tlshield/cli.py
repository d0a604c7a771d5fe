"""The ``tlshield`` command line."""

from __future__ import annotations

import argparse
import itertools
import sys
from collections.abc import Sequence

import numpy as np

from tlshield.envs.channel import STATE_DIM, channel_task_spec


def _straight_path(waypoints: Sequence[tuple[float, float]], steps_per_leg: int) -> np.ndarray:
    points = [np.asarray(waypoints[0], dtype=float)]
    for a, b in itertools.pairwise(waypoints):
        for k in range(1, steps_per_leg + 1):
            points.append(np.asarray(a) + (np.asarray(b) - np.asarray(a)) * k / steps_per_leg)
    return np.array(points)


def _demo(args: argparse.Namespace) -> int:
    spec = channel_task_spec(half_width=args.half_width, goal_radius=args.goal_radius)
    goals = np.array([[1.0, 2.0], [3.0, 1.0], [5.0, 5.2]])
    obstacles = np.array([[1.0, 3.0], [4.0, 2.0]])
    scene = np.concatenate([goals.ravel(), obstacles.ravel()])

    def trajectory(waypoints: Sequence[tuple[float, float]]) -> np.ndarray:
        xy = _straight_path(waypoints, steps_per_leg=args.steps // (len(waypoints) - 1))
        traj = np.zeros((len(xy), STATE_DIM))
        traj[:, :2] = xy
        traj[:, 3:] = scene
        return traj

    cases = {
        "g1 then g3, inside the channel": trajectory([(0.0, 0.0), (1.0, 2.0), (5.0, 5.2)]),
        "g3 first (violates !g3 U (g1|g2))": trajectory([(0.0, 0.0), (5.0, 5.2), (1.0, 2.0)]),
        "leaves the channel on the way": trajectory([(0.0, 0.0), (2.5, 0.0), (1.0, 2.0), (5, 5.2)]),
        "never reaches a goal": trajectory([(0.0, 0.0), (1.0, 1.0)]),
    }
    print(f"task: {spec}")
    print(f"atoms: {', '.join(spec.atoms)}")
    print(f"{'trajectory':<40} {'steps':>6} {'robustness':>11} satisfied")
    for name, traj in cases.items():
        rho = spec.robustness(traj)
        print(f"{name:<40} {len(traj) - 1:>6} {rho:>11.4f} {spec.satisfied(traj)}")
    batch = np.stack([cases["g1 then g3, inside the channel"]] * 4)
    print(f"batch of {len(batch)}: {spec.robustness_batch(batch)}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``tlshield`` command."""
    parser = argparse.ArgumentParser(
        prog="tlshield",
        description="Temporal-logic guided safe reinforcement learning with CBF shields.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="robustness of the paper's task on sample trajectories")
    demo.add_argument("--steps", type=int, default=200, help="trajectory length T (default 200)")
    demo.add_argument("--half-width", type=float, default=1.5, help="channel half-width w")
    demo.add_argument("--goal-radius", type=float, default=0.5, help="goal radius")
    demo.set_defaults(handler=_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``tlshield`` and ``python -m tlshield``."""
    args = build_parser().parse_args(argv)
    if getattr(args, "steps", 1) < 2:
        print("tlshield: error: --steps must be at least 2", file=sys.stderr)
        return 2
    return int(args.handler(args))
