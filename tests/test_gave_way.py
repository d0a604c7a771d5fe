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
    assert shield_info(out, np.zeros(2))["gave_way"] is None


@pytest.mark.parametrize("first", ["wall", "floor"])
def test_the_declared_order_decides_who_gives_way_over_the_slack_weights(first: str) -> None:
    """``give_way=[...]``: the first-named barrier gives way and the other holds exactly, even
    where the slack weights say the opposite (issue 57, item 4: a declared priority)."""
    other = "floor" if first == "wall" else "wall"
    # The weights favour `other` giving way (1e-3 against 1): the declared order overrides.
    barriers = {"wall": WALL, "floor": FLOOR}
    weighted = {first: (barriers[first], 1.0), other: (barriers[other], 1e-3)}
    sh = tlshield.Shield(
        SPEC,
        tlshield.SingleIntegrator([0, 1]),
        barriers=weighted,
        give_way=[first],
        **GAINS,
    )
    out = sh.filter(np.array([0.5, 0.0]), 0, [0.0, 0.0])
    assert out.status == tlshield.Status.RELAXED and out.gave_way is not None
    assert out.gave_way[0] == first
    # The one that held keeps its row: the floor dx/dt >= 1.5, the wall dx/dt <= 0.5.
    if other == "floor":
        assert out.action[0] >= 1.5 - 1e-7
    else:
        assert out.action[0] <= 0.5 + 1e-7
    # Without the declaration, the weights decide: `other` gives way.
    plain = tlshield.Shield(SPEC, tlshield.SingleIntegrator([0, 1]), barriers=weighted, **GAINS)
    assert plain.filter(np.array([0.5, 0.0]), 0, [0.0, 0.0]).gave_way[0] == other  # type: ignore[index]


def test_a_barrier_gives_way_only_when_those_named_before_it_cannot_restore_feasibility() -> None:
    """``give_way=["ceiling", "wall"]``: relaxing the ceiling (not in conflict) alone cannot
    help, so the wall gives way next; the ceiling takes no slack, and the floor, unnamed, holds."""
    ceiling = tlshield.Inside(tlshield.Halfspace([0.0, -1.0], 5.0))  # y < 5
    sh = tlshield.Shield(
        SPEC,
        tlshield.SingleIntegrator([0, 1]),
        barriers={"wall": WALL, "floor": FLOOR, "ceiling": ceiling},
        give_way=["ceiling", "wall"],
        **GAINS,
    )
    out = sh.filter(np.array([0.5, 0.0]), 0, [0.0, 0.0])
    assert out.gave_way is not None and out.gave_way[0] == "wall"
    assert out.action[0] >= 1.5 - 1e-7  # the floor held
    # Batches follow the same order.
    batch = sh.filter_batch(np.array([[0.5, 0.0]] * 3), np.zeros(3, int), np.zeros((3, 2)))
    np.testing.assert_allclose(batch.action, np.repeat(out.action[None], 3, axis=0), atol=1e-9)


def test_the_order_is_checked_where_it_is_given_and_names_atoms_too() -> None:
    kw = {"barriers": {"wall": WALL}, **GAINS}
    model = tlshield.SingleIntegrator([0, 1])
    with pytest.raises(
        tlshield.ShieldError, match=r'give_way: "shelf" is neither.*\["wall", "g"\]'
    ):
        tlshield.Shield(SPEC, model, give_way=["shelf"], **kw)
    with pytest.raises(tlshield.ShieldError, match='"wall" is named twice'):
        tlshield.Shield(SPEC, model, give_way=["wall", "wall"], **kw)
    with pytest.raises(TypeError, match="one string"):
        tlshield.Shield(SPEC, model, give_way="wall", **kw)  # type: ignore[arg-type]
    # An atom of the task (its safe-set literal) may be named, and the order survives a pickle.
    import pickle

    sh = tlshield.Shield(SPEC, model, give_way=["g", "wall"], **kw)
    assert pickle.loads(pickle.dumps(sh)).__reduce__()[1][3]["give_way"] == ["g", "wall"]


def test_a_batch_names_who_gave_way_row_by_row() -> None:
    """``FilterBatch.gave_way`` (and the monitor batch's) is what ``filter`` says, per row."""
    ceiling = tlshield.Inside(tlshield.Halfspace([0.0, -1.0], 5.0))  # y < 5
    barriers = {"wall": (WALL, 1e-3), "floor": FLOOR, "ceiling": ceiling}
    sh = tlshield.Shield(SPEC, tlshield.SingleIntegrator([0, 1]), barriers=barriers, **GAINS)
    rng = np.random.default_rng(0)
    states = rng.uniform([-1.0, -1.0], [3.0, 6.0], (64, 2))
    a_rl = rng.uniform(-1.0, 1.0, (64, 2))
    batch = sh.filter_batch(states, np.zeros(64, int), a_rl)
    want = [sh.filter(s, 0, a).gave_way for s, a in zip(states, a_rl, strict=True)]
    assert batch.gave_way == want
    assert sum(g is not None for g in want) >= 10  # rows did give way
    monitors = tlshield.MonitorBatch(sh.automaton, 64)
    monitors.reset(states)
    assert sh.filter_monitors(monitors, a_rl).gave_way == want
