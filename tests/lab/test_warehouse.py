"""Warehouse scenarios (``tlshield.lab.warehouse``; docs/concepts/deadlock.md, "Warehouse"):
P, then D inside an alcove of shelves, a forklift crossing the aisle. A few seeded episodes per
cell; the full tables are the module's command line. Success is asserted only in the cells
that reach their goals today; every cell asserts that nothing is entered."""

from __future__ import annotations

import numpy as np
import pytest

from tlshield.lab import routing, warehouse

#: The cells whose episodes do not all reach D today (the 30-episode table in the docs): the
#: bicycle's greedy seeker in the alcove; in the covered variant, the seekers that press at the
#: pallet over D's centre and stay (ThrustTurn's at seed 0, the bicycle's).
ALCOVE_SHORT = {("bicycle", "seeker")}
COVERED_SHORT = {("thrust_turn", "seeker"), ("bicycle", "seeker")}


def _inside_a_shelf(p: np.ndarray, variant: str) -> bool:
    return any(np.linalg.norm(p - c) < r for c, r in warehouse.shelves(variant))


def test_the_layouts_are_what_the_docs_say() -> None:
    """D is clear in the alcove; the covered variant's pallet holds D's centre and leaves a
    part of D free; the enclosed variant's shelves close the alcove's mouth."""
    assert routing.CLF_SHARE == 0.5
    assert not _inside_a_shelf(warehouse.D, "alcove")
    assert _inside_a_shelf(warehouse.D, "covered")
    free = warehouse.D + np.array([0.0, warehouse.COVERED_D_RADIUS - 0.05])
    assert np.linalg.norm(free - warehouse.D) < warehouse.d_radius("covered")
    assert not _inside_a_shelf(free, "covered")
    # Along the alcove's mouth (y = ROW_Y), every point is inside a shelf when enclosed.
    xs = np.linspace(warehouse.ALCOVE_WEST, warehouse.ALCOVE_EAST, 41)
    assert all(_inside_a_shelf(np.array([x, warehouse.ROW_Y]), "enclosed") for x in xs)
    assert not _inside_a_shelf(np.array([2.4, warehouse.ROW_Y]), "alcove")


@pytest.mark.parametrize("robot", warehouse.ROBOTS)
@pytest.mark.parametrize("driver", warehouse.DRIVERS)
def test_the_alcove_is_reached_past_the_forklift_without_entering(robot: str, driver: str) -> None:
    for seed in range(3):
        e = warehouse.episode("alcove", robot, driver, seed)
        assert e.entries == 0, f"{robot}/{driver}/seed {seed}: {e.entries} steps inside"
        if (robot, driver) not in ALCOVE_SHORT:
            assert e.success, f"{robot}/{driver}/seed {seed}: ended at {e.end}"


@pytest.mark.parametrize("robot", warehouse.ROBOTS)
def test_a_covered_goal_is_reached_at_its_free_part(robot: str) -> None:
    """A pallet covers D's centre: the shield alone reaches D's free part, flagging no step
    unreachable; no driver enters a shelf, the pallet or the forklift (a seeker turning hard at
    the pallet's rim once did, by a millimetre, before the bent steps' rows were settled)."""
    for driver in warehouse.DRIVERS:
        e = warehouse.episode("covered", robot, driver, 0)
        assert e.entries == 0, f"{robot}/{driver}: {e.entries} steps inside"
        assert e.d_steps > 0
        if (robot, driver) not in COVERED_SHORT:
            assert e.success and e.unreachable == 0, f"{robot}/{driver}: ended at {e.end}"


@pytest.mark.parametrize(("robot", "driver"), [("single", "shield"), ("bicycle", "seeker")])
def test_an_enclosed_goal_is_reported_unreachable_at_every_step(robot: str, driver: str) -> None:
    """Once P is visited, every step's ``goal_unreachable`` is set, and none before."""
    e = warehouse.episode("enclosed", robot, driver, 0)
    assert not e.success and e.entries == 0
    assert e.d_steps > 1000
    assert e.unreachable == e.d_steps
    assert e.p_unreachable == 0


def test_the_command_line_prints_a_table(capsys: pytest.CaptureFixture[str]) -> None:
    warehouse.main(["--episodes", "1", "--variant", "alcove"])
    out = capsys.readouterr().out
    assert "| bicycle | seeker |" in out and "1 episodes per cell" in out
