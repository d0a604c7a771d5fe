"""A goal a shelf partly covers: the routed CLF aims at the nearest point of the goal's free part
(``guidance/free.rs``), so every robot of the routing lab reaches it, from the free part on
its side or behind the shelf, without entering the shelf; and the goal is not reported
unreachable. A goal the shelf covers whole still is (``tests/test_unreachable.py``)."""

from __future__ import annotations

import numpy as np
import pytest

from tlshield import Avoid, Ball, Monitor, Shield, Spec
from tlshield.lab import routing

GOAL_RADIUS = 0.3
SHELF_RADIUS = 0.3
#: The shelf's centre from the goal's along x: beyond the goal (its free part faces the
#: robot) or before it (the free part lies behind the shelf).
OFFSETS = (0.15, -0.15)


def _episode(robot: str, encoding: str, offset: float, seed: int) -> tuple[bool, int, int]:
    """(reached, steps inside the shelf, steps reported unreachable) of one seeded episode."""
    rng = np.random.default_rng(seed)
    start = routing.START + rng.uniform(-0.1, 0.1, 2)
    goal = routing.GOAL + rng.uniform(-0.1, 0.1, 2)
    shelf = goal + np.array([offset, 0.0])
    r = routing.robot(robot)
    goal_ball = Ball([0, 1], GOAL_RADIUS, center=list(goal))
    shelf_ball = Ball([0, 1], SHELF_RADIUS, center=list(shelf))
    if encoding == "formula":
        spec, barriers = Spec("!o U g", {"o": shelf_ball, "g": goal_ball}), None
    else:
        spec, barriers = Spec("F g", {"g": goal_ball}), {"!o": Avoid(shelf_ball)}
    shield = Shield(spec, r.model, barriers=barriers, dt=routing.DT, **r.shield_kwargs)
    monitor = Monitor(shield.automaton)
    s = r.start(start)
    monitor.reset(s)
    inside = unreachable = 0
    for _ in range(routing.HORIZON):
        out = shield.filter_monitor(monitor, np.zeros(2))
        unreachable += bool(out.goal_unreachable)
        s = r.model.step(s, out.action, routing.DT)
        monitor.advance(s)
        inside += bool(np.linalg.norm(s[:2] - shelf) < SHELF_RADIUS)
        if np.linalg.norm(s[:2] - goal) < GOAL_RADIUS:
            return True, inside, unreachable
    return False, inside, unreachable


@pytest.mark.parametrize("robot", routing.ALL_ROBOTS)
@pytest.mark.parametrize("encoding", routing.ENCODINGS)
@pytest.mark.parametrize("offset", OFFSETS)
def test_a_partly_covered_goal_is_reached_at_its_free_part(
    robot: str, encoding: str, offset: float
) -> None:
    for seed in range(2):
        reached, inside, unreachable = _episode(robot, encoding, offset, seed)
        assert (reached, inside, unreachable) == (True, 0, 0), (seed, inside, unreachable)
