"""A policy's turn into a blocking obstacle is released to the CLF (its box widens on the turn
input so that ``a_clf`` can cancel it), for a disc that stays put. A disc that moves (its
centre read from the state) is left to its barrier: releasing there cost Channel-v0's shielded
agents give-ways and contacts with the moving obstacles."""

from __future__ import annotations

import numpy as np
import pytest

import tlshield

GAINS = {
    "alpha": 1.0,
    "c3": 1.0,
    "k": 30.0,
    "cbf_bounds": ((-3.0, -9.0), (3.0, 9.0)),
    "clf_bounds": ((-0.5, -1.5), (0.5, 1.5)),
}
SPEC = tlshield.Spec("F g", {"g": tlshield.Ball([0, 1], 0.2, center=[3.0, 0.0])})


def _turn(moving: bool, rl_turn: float) -> float:
    """The CLF's turn when a unicycle heading at a disc ahead and to its left is turned by the
    policy at ``rl_turn``."""
    if moving:
        disc = tlshield.Ball([0, 1], 0.5, center_dims=[3, 4])
        s = np.array([0.0, 0.0, 0.0, 1.0, 0.3])
    else:
        disc = tlshield.Ball([0, 1], 0.5, center=[1.0, 0.3])
        s = np.zeros(3)
    shield = tlshield.Shield(
        SPEC, tlshield.Unicycle(0.1), barriers={"o": tlshield.Avoid(disc)}, **GAINS
    )
    out = shield.filter(s, 0, [0.5, rl_turn])
    assert out.status == tlshield.Status.SOLVED
    return float(out.a_clf[1])


def test_a_turn_into_a_still_disc_is_released_to_the_clf() -> None:
    # Turning left (into the disc): the CLF cancels it past its own box (-1.5).
    assert _turn(False, 3.0) == pytest.approx(-4.5)
    # Turning right (away from it): nothing is released.
    assert _turn(False, -3.0) >= -1.5 - 1e-9


def test_a_turn_into_a_moving_disc_is_left_to_its_barrier() -> None:
    assert _turn(True, 3.0) >= -1.5 - 1e-9
