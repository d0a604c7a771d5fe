"""Models whose step bends with the action (the acceleration unicycle, the bicycle): their
second-order sampled rows are linearised again at the action found until it settles, so a
policy turning hard at a disc's rim never takes the sampled state inside it (linearised once at
``a = 0`` such a policy ended about a millimetre inside), and ``dL/da_rl`` of that fixed point
equals central differences of the action."""

from __future__ import annotations

import numpy as np
import pytest

from tests.test_routed_reference import assert_vjp_matches_differences
from tlshield import Status
from tlshield.lab import routing

DISC = (np.array([0.0, 0.0]), 0.5)


def _pressing(robot: str, seed: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """States on a disc's rim, heading along it, with RL actions that push and turn into it."""
    rng = np.random.default_rng(seed)
    model = routing.robot(robot)
    states, actions = [], []
    for _ in range(200):
        angle = rng.uniform(-np.pi, np.pi)
        p = DISC[0] + (DISC[1] + rng.uniform(0.0, 0.05)) * np.array([np.cos(angle), np.sin(angle)])
        s = model.start(p)
        s[2] = angle + np.pi / 2 + rng.uniform(-0.6, 0.6)  # roughly along the rim
        s[3] = rng.uniform(0.1, 0.6)
        states.append(s)
        turn_in = 1.0 if rng.random() < 0.5 else -1.0
        actions.append(np.array([rng.uniform(0.0, 1.0), turn_in * rng.uniform(0.5, 1.0)]))
    return states, actions


@pytest.mark.parametrize("robot", ["accel_unicycle", "bicycle"])
def test_a_hard_turn_at_the_rim_keeps_the_sampled_state_out(robot: str) -> None:
    """Closed loop: a seeker driving at a goal behind the disc, turning at its full rate; the
    step after every shielded action stays outside the disc."""
    model = routing.robot(robot)
    worst = np.inf
    for seed in range(10):
        rng = np.random.default_rng(seed)
        goal = np.array([2.0, 0.0]) + rng.uniform(-0.1, 0.1, 2)
        start = np.array([-2.0, 0.0]) + rng.uniform(-0.1, 0.1, 2)
        shield = routing.shield_for(robot, [DISC], goal, "barriers", route=True)
        s = model.start(start)
        q = shield.automaton.initial
        for _ in range(400):
            out = shield.filter(s, q, model.seeker(s, goal))
            s = model.model.step(s, out.action, routing.DT)
            worst = min(worst, float(np.linalg.norm(s[:2] - DISC[0]) - DISC[1]))
    assert worst >= 0.0, worst


@pytest.mark.parametrize("robot", ["accel_unicycle", "bicycle"])
def test_the_settled_action_s_gradient_is_exact(robot: str) -> None:
    states, actions = _pressing(robot, 3)
    shield = routing.shield_for(robot, [DISC], routing.GOAL, "barriers", route=True)
    s, a = np.array(states), np.array(actions)
    q = np.full(len(s), shield.automaton.initial)
    batch = shield.filter_batch(s, q, a)
    v = np.random.default_rng(0).normal(size=a.shape)
    ga, _, flags = shield.vjp_batch(s, q, a, v, state_grad=False)
    # Rows the shield corrected, solved, at no kink: their gradient is a two-sided one.
    corrected = np.abs(batch.action - a).max(axis=1) > 1e-3
    exact = (batch.status == Status.SOLVED) & corrected & ((flags & np.uint8(0xEF)) == 0)
    assert exact.sum() >= 40, exact.sum()
    assert_vjp_matches_differences(shield, s, q, a, v, ga, exact)
