"""Routing around walls: a disc against a wall closes the way on that side, and the shortest
way round the disc alone would run through the wall. The router drops the corners beyond the
half-planes the state is kept in (an ``Inside`` half-space, an ``Avoid`` one, or a half-space
literal the task keeps true), so every robot of the routing lab goes round the open side;
without walls it parked at the wall, against the disc."""

from __future__ import annotations

import numpy as np
import pytest

from tlshield import Avoid, Ball, Halfspace, Inside, Monitor, Shield, Spec
from tlshield.lab import routing

#: The wall: y <= WALL_Y, which cuts into the disc's top, so only its lower side is open.
WALL_Y = 0.45
ENCODINGS = ("inside", "avoid", "formula")


def _episode(robot: str, encoding: str, seed: int) -> tuple[bool, int]:
    """(reached, steps past the wall or inside the disc) of one seeded episode."""
    rng = np.random.default_rng(seed)
    start = np.array([-2.0, 0.35]) + rng.uniform(-0.05, 0.05, 2)
    goal = np.array([2.0, 0.35]) + rng.uniform(-0.05, 0.05, 2)
    r = routing.robot(robot)
    n = len(r.start(start))
    below = np.zeros(n)
    below[1] = -1.0  # rho = WALL_Y - y: holds below the wall
    disc = Ball([0, 1], 0.5, center=[0.0, 0.0])
    g = Ball([0, 1], routing.GOAL_RADIUS, center=list(goal))
    if encoding == "inside":
        spec = Spec("F g", {"g": g})
        barriers = {"!o": Avoid(disc), "room": Inside(Halfspace(list(below), WALL_Y))}
    elif encoding == "avoid":
        spec = Spec("F g", {"g": g})
        barriers = {"!o": Avoid(disc), "!out": Avoid(Halfspace(list(-below), -WALL_Y))}
    else:
        spec = Spec("(!o & room) U g", {"o": disc, "room": Halfspace(list(below), WALL_Y), "g": g})
        barriers = None
    shield = Shield(spec, r.model, barriers=barriers, dt=routing.DT, **r.shield_kwargs)
    monitor = Monitor(shield.automaton)
    s = r.start(start)
    monitor.reset(s)
    outside = 0
    for _ in range(routing.HORIZON):
        out = shield.filter_monitor(monitor, np.zeros(2))
        s = r.model.step(s, out.action, routing.DT)
        monitor.advance(s)
        outside += bool(s[1] > WALL_Y or np.linalg.norm(s[:2]) < 0.5)
        if np.linalg.norm(s[:2] - goal) < routing.GOAL_RADIUS:
            return True, outside
    return False, outside


@pytest.mark.parametrize("robot", routing.ALL_ROBOTS)
@pytest.mark.parametrize("encoding", ENCODINGS)
def test_the_way_round_a_disc_against_a_wall_takes_the_open_side(robot: str, encoding: str) -> None:
    for seed in range(2):
        assert _episode(robot, encoding, seed) == (True, 0), seed
