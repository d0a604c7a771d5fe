"""A car (the kinematic bicycle: it turns only while moving) stopped with its nose at the rim
of a disc it heads into backs out, and a policy's throttle into that disc does not hold it
there: it is released to the CLF's box, as a turn into a blocking disc is
(``tests/test_routed_reference.py``). Without either, the routing lab's car parked
nose-first among eight random discs, and its greedy seeker in the warehouse's alcove."""

from __future__ import annotations

import numpy as np

import tlshield
from tests.test_routed_reference import assert_released_rows_exact, clf_box_rows
from tlshield.lab import routing


def _nose_at_rim(rng: np.random.Generator, obstacles: list, count: int) -> np.ndarray:
    """Car states at rest (or creeping) with the nose within 0.1 of a disc's radius from its
    rim, heading into it, outside every disc."""
    states: list[np.ndarray] = []
    while len(states) < count:
        c, r = obstacles[rng.integers(len(obstacles))]
        bearing = rng.uniform(-np.pi, np.pi)
        p = c + (r + rng.uniform(0.002, 0.09) * r) * np.array([np.cos(bearing), np.sin(bearing)])
        if any(np.linalg.norm(p - o) - ro < 0.002 for o, ro in obstacles):
            continue
        # Heading into the disc, up to 60 degrees off its centre.
        theta = bearing + np.pi + rng.uniform(-np.pi / 3, np.pi / 3)
        states.append(np.array([p[0], p[1], theta, rng.uniform(-0.02, 0.02)]))
    return np.array(states)


def test_a_throttle_into_a_disc_at_the_nose_widens_only_the_clf_box_exactly() -> None:
    rng = np.random.default_rng(3)
    obstacles = routing.layout("random8", rng)
    sh = routing.shield_for("bicycle", obstacles, routing.GOAL, "barriers", route=True)
    car = routing.robot("bicycle")
    bounds = car.shield_kwargs["clf_bounds"]
    s_arr = _nose_at_rim(rng, obstacles, 200)
    a_arr = np.array([car.seeker(s, routing.GOAL) for s in s_arr])

    def released(problem: dict, a: np.ndarray) -> bool:
        widened = clf_box_rows(problem, sh.num_inputs, bounds)
        # The throttle is released exactly where the policy pushes the nose in.
        assert widened[0] == (a[0] > 0.0), f"throttle {a[0]}, widened {widened[0]}"
        return bool(widened[0])

    assert_released_rows_exact(sh, s_arr, a_arr, released, all_solved=True)


def _drive(s: np.ndarray, goal: np.ndarray, obstacles: list, seek: bool) -> tuple[bool, float]:
    """(reached, the lowest speed) of the car from ``s`` to ``goal``, by the shield alone or
    through a greedy seeker; never inside a disc."""
    sh = routing.shield_for("bicycle", obstacles, goal, "barriers", route=True)
    car = routing.robot("bicycle")
    monitor = tlshield.Monitor(sh.automaton)
    monitor.reset(s)
    slowest = 0.0
    for _ in range(routing.HORIZON):
        a_rl = car.seeker(s, goal) if seek else np.zeros(2)
        out = sh.filter_monitor(monitor, a_rl)
        s = car.model.step(s, out.action, routing.DT)
        assert all(np.linalg.norm(s[:2] - c) >= r for c, r in obstacles)
        slowest = min(slowest, float(s[3]))
        monitor.advance(s)
        if np.linalg.norm(s[:2] - goal) < routing.GOAL_RADIUS:
            return True, slowest
    return False, slowest


def test_nose_first_at_a_disc_the_car_backs_out_and_goes_round() -> None:
    # At rest with its nose on a disc's rim, 30 degrees off its centre, the goal beyond it.
    obstacles = [(np.array([0.0, 0.0]), 0.4)]
    goal = np.array([1.5, 0.3])
    for seek in (False, True):
        s = np.array([-0.41 * np.cos(0.5), -0.41 * np.sin(0.5), 0.5 - np.pi / 6, 0.0])
        reached, slowest = _drive(s, goal, obstacles, seek)
        assert reached, f"seeker {seek}"
        assert slowest < -0.05, f"seeker {seek}: never backed up ({slowest})"
