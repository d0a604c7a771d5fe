"""A car (the kinematic bicycle: it turns only while moving) driven by the shield alone reaches
a goal at any bearing: it gets moving to turn, backs up where the goal is behind its axle line
or inside its turning circle, and drives on once clear (``scripts/robot_reach.py``'s scene:
an open floor, the goal 2 m away, the routing lab's gains and the recommended CLF box). A
custom model declaring its ``heading`` and ``speed`` is the same car."""

from __future__ import annotations

import importlib.util
import pickle
from pathlib import Path

import numpy as np
import pytest

import tlshield
from tlshield.lab import routing

_SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "robot_reach.py"
_spec = importlib.util.spec_from_file_location("robot_reach", _SCRIPT)
assert _spec is not None and _spec.loader is not None
robot_reach = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(robot_reach)


def _drive(shield: tlshield.Shield, model: object, goal: np.ndarray) -> tuple[bool, float]:
    """(reached, the lowest speed on the way) from rest at the origin, heading 0."""
    s = np.zeros(4)
    monitor = tlshield.Monitor(shield.automaton)
    monitor.reset(s)
    slowest = 0.0
    for _ in range(routing.HORIZON):
        out = shield.filter_monitor(monitor, np.zeros(2))
        s = model.step(s, out.action, routing.DT)
        slowest = min(slowest, float(s[3]))
        monitor.advance(s)
        if np.linalg.norm(s[:2] - goal) < routing.GOAL_RADIUS:
            return True, slowest
    return False, slowest


def _car_shield(model: object, **declared: int) -> tlshield.Shield:
    gains = routing._second_order(routing.SPEED, routing.TURN_GAIN)
    goal = tlshield.Ball([0, 1], routing.GOAL_RADIUS, center=list(GOAL_ABEAM))
    return tlshield.Shield(
        tlshield.Spec("F goal", {"goal": goal}), model, dt=routing.DT, **gains, **declared
    )


GOAL_ABEAM = np.array([0.0, 2.0])


@pytest.mark.parametrize("bearing", robot_reach.BEARINGS)
def test_the_bicycle_reaches_a_goal_at_any_bearing(bearing: int) -> None:
    assert all(robot_reach.episode("bicycle", bearing, seed) for seed in range(3))


def test_abeam_it_backs_up_and_a_declared_custom_car_does_the_same() -> None:
    bike = tlshield.KinematicBicycle(0.5)
    reached, slowest = _drive(_car_shield(bike), bike, GOAL_ABEAM)
    assert reached and slowest < -0.05  # a three-point turn: it reversed on the way
    custom = tlshield.ControlAffine(
        lambda s: np.array([s[3] * np.cos(s[2]), s[3] * np.sin(s[2]), 0.0, 0.0]),
        lambda s: np.array([[0.0, 0.0], [0.0, 0.0], [0.0, s[3] / 0.5], [1.0, 0.0]]),
        state_dim=4,
        inputs=2,
    )
    declared = _car_shield(custom, heading=2, speed=3)
    # The same car up to rounding (the custom model's Jacobian is a finite difference).
    again, slowest_again = _drive(declared, bike, GOAL_ABEAM)
    assert again and slowest_again == pytest.approx(slowest, abs=1e-6)
    back = pickle.loads(pickle.dumps(bike_shield := _car_shield(bike, speed=3)))
    s = np.array([0.0, 0.0, 0.0, 0.1])
    np.testing.assert_array_equal(
        back.filter(s, 0, [0.0, 0.0]).action, bike_shield.filter(s, 0, [0.0, 0.0]).action
    )
    # Undeclared, the custom car parks: nothing tells the shield it must move to turn.
    assert not _drive(_car_shield(custom, heading=2), bike, GOAL_ABEAM)[0]


def test_a_speed_on_the_position_or_the_heading_is_refused() -> None:
    bike = tlshield.KinematicBicycle(0.5)
    with pytest.raises(tlshield.ShieldError, match="speed = 1"):
        _car_shield(bike, speed=1)
    with pytest.raises(tlshield.ShieldError, match="speed = 2"):
        _car_shield(bike, heading=2, speed=2)
