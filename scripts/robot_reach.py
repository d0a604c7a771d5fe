"""Each robot's reach with the shield alone: the goal 2 m away at a bearing from the robot's
heading (ahead, 45 degrees, abeam, 135 degrees, behind), on an open floor, the policy's action
zero (CBF + CLF, routing on). A robot that must turn to move sideways, a car most of all, may
never get there: this table says which.

The robots and their gains are ``tlshield.lab.routing``'s (its recommended CLF box, half the
limits, and k by the rule), the kinematic bicycle (wheelbase 0.5 m; inputs acceleration and
``tan(steer)``, each bounded by 1) among them with the acceleration-level robots' gains. Each
cell is the share of seeded episodes (start jittered by up to 0.1 m and 0.1 rad) that reach the
goal disc (radius 0.2 m) within 40 s.

Run: ``.venv/bin/python scripts/robot_reach.py [--episodes 20]``.
"""

from __future__ import annotations

import argparse

import numpy as np

from tlshield import Ball, Monitor, Shield, Spec
from tlshield.lab import routing

BEARINGS = (0, 45, 90, 135, 180)
DISTANCE = 2.0
ROBOTS = routing.ALL_ROBOTS


def _model_and_gains(name: str) -> tuple[object, dict, int]:
    """The model, the shield's gains and the state's length (the routing lab's robot)."""
    r = routing.robot(name)
    return r.model, dict(r.shield_kwargs), len(r.start(np.zeros(2)))


def episode(name: str, bearing: float, seed: int) -> bool:
    """Whether one seeded episode reaches the goal."""
    rng = np.random.default_rng(seed)
    model, gains, n = _model_and_gains(name)
    s = np.zeros(n)
    s[:2] = rng.uniform(-0.1, 0.1, 2)
    if n >= 3:
        s[2] = rng.uniform(-0.1, 0.1)
    angle = np.radians(bearing)
    goal = np.array([DISTANCE * np.cos(angle), DISTANCE * np.sin(angle)])
    spec = Spec("F goal", {"goal": Ball([0, 1], routing.GOAL_RADIUS, center=list(goal))})
    shield = Shield(spec, model, dt=routing.DT, **gains)
    monitor = Monitor(shield.automaton)
    monitor.reset(s)
    for _ in range(routing.HORIZON):
        out = shield.filter_monitor(monitor, np.zeros(2))
        s = model.step(s, out.action, routing.DT)
        monitor.advance(s)
        if np.linalg.norm(s[:2] - goal) < routing.GOAL_RADIUS:
            return True
    return False


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20)
    args = parser.parse_args(argv)
    print("| robot | " + " | ".join(f"{b} deg" for b in BEARINGS) + " |")
    print("|---|" + "---:|" * len(BEARINGS))
    for name in ROBOTS:
        rates = [
            sum(episode(name, b, seed) for seed in range(args.episodes)) / args.episodes
            for b in BEARINGS
        ]
        print(f"| {name} | " + " | ".join(f"{r:.2f}" for r in rates) + " |")


if __name__ == "__main__":
    main()
