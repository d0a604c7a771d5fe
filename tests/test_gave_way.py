"""Every give-way is reported (issue 57, item 4): when the QP must be relaxed,
``FilterResult.gave_way`` names the barrier whose row took the most slack, and by how much, and
``info["shield"]`` carries it; the lighter barrier (the smaller slack weight) is the one that
gives way, whichever it is."""

from __future__ import annotations

import numpy as np
import pytest

import tlshield
from tlshield.tracking import shield_info

SPEC = tlshield.Spec("F g", {"g": tlshield.Ball([0, 1], 0.3, center=[0.5, 3.0])})
GAINS = {"alpha": 1.0, "c3": 1.0, "k": 1e4, "cbf_bounds": (-1.0, 1.0), "clf_bounds": (-1.0, 1.0)}
WALL = tlshield.Inside(tlshield.Halfspace([-1.0, 0.0], 1.0))  # x < 1
FLOOR = tlshield.Inside(tlshield.Halfspace([1.0, 0.0], -2.0))  # x > 2: violated at x = 0.5


@pytest.mark.parametrize(("light", "heavy"), [("floor", "wall"), ("wall", "floor")])
def test_the_lighter_barrier_gives_way_and_is_named(light: str, heavy: str) -> None:
    # At x = 0.5 the floor asks dx/dt >= 1.5 and the wall dx/dt <= 0.5: one must give way.
    rows = {"wall": WALL, "floor": FLOOR}
    barriers = {light: (rows[light], 1e-3), heavy: (rows[heavy], 1.0)}
    sh = tlshield.Shield(SPEC, tlshield.SingleIntegrator([0, 1]), barriers=barriers, **GAINS)
    out = sh.filter(np.array([0.5, 0.0]), 0, [0.0, 0.0])
    assert out.status == tlshield.Status.RELAXED
    assert out.gave_way is not None
    name, slack = out.gave_way
    assert name == light and slack == pytest.approx(out.slack) and slack > 0.0
    assert shield_info(out, np.zeros(2))["gave_way"] == out.gave_way


def test_nothing_gave_way_on_a_solved_step() -> None:
    sh = tlshield.Shield(SPEC, tlshield.SingleIntegrator([0, 1]), barriers={"wall": WALL}, **GAINS)
    out = sh.filter(np.array([0.5, 0.0]), 0, [0.3, 0.0])
    assert out.status == tlshield.Status.SOLVED and out.gave_way is None
    assert shield_info(None, np.zeros(2))["gave_way"] is None
