"""Safety-Gymnasium's pseudo-lidar, read without MuJoCo's positions
(``tlshield.envs.safety_gym.lidar``): the forward model equals Safety-Gymnasium's own bins
(an independent reference: the installed env), and what the bins are read to say holds for
every layout of objects (property tests): no centre nearer than its bin's floor, a single
object read exactly, a clean triple read exactly among others, and the cover's discs no
farther than any centre they stand for, up to twice the robot's motion since the reading."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tlshield.envs.safety_gym import lidar as L

LIDAR = L.Lidar()
# Centres within the lidar's range and beyond it, never on the origin.
point = st.tuples(
    st.floats(0.05, 3.5, allow_nan=False), st.floats(-np.pi, np.pi, allow_nan=False)
).map(lambda da: np.array([da[0] * np.cos(da[1]), da[0] * np.sin(da[1])]))
layouts = st.lists(point, min_size=1, max_size=12)


def _bin(p: np.ndarray) -> int:
    return int((np.arctan2(p[1], p[0]) % (2 * np.pi)) / LIDAR.width) % LIDAR.bins


@pytest.mark.parametrize("task", ["SafetyPointGoal2-v0", "SafetyCarGoal1-v0"])
def test_the_forward_model_is_safety_gymnasiums_lidar(task: str) -> None:
    from tlshield.envs.safety_gym import SafetyGoalEnv

    env = SafetyGoalEnv(task, config="rl")
    try:
        for seed in range(3):
            obs, _ = env.reset(seed=seed)
            for _ in range(5):
                obs, *_ = env.step(env.action_space.sample())
            data = env._env.task.data
            body = data.body("agent")
            rot = body.xmat.reshape(3, 3)
            for name in ("goal", "hazards", "vases"):
                sg = env._env.task
                if name == "goal":
                    centres = [data.body("goal").xpos]
                else:
                    count = getattr(sg, name).num
                    centres = [data.body(f"{name[:-1]}{i}").xpos for i in range(count)]
                ego = [(rot.T @ (np.array([c[0], c[1], 0.0]) - body.xpos))[:2] for c in centres]
                want = env.lidar(obs, name)
                np.testing.assert_allclose(L.reading(ego), want, atol=1e-12, rtol=0)
    finally:
        env.close()


@settings(max_examples=300, deadline=None)
@given(layouts)
def test_no_centre_is_nearer_than_its_bins_floor(points: list[np.ndarray]) -> None:
    floors = L.floors(L.reading(points))
    for p in points:
        assert np.hypot(*p) >= floors[_bin(p)] - 1e-12


@settings(max_examples=300, deadline=None)
@given(point)
def test_a_single_object_is_read_exactly(p: np.ndarray) -> None:
    found = L.nearest(L.reading([p]))
    d = float(np.hypot(*p))
    if d >= LIDAR.max_dist:
        assert found is None
        return
    assert found is not None
    got = found[0] * np.array([np.cos(found[1]), np.sin(found[1])])
    np.testing.assert_allclose(got, p, atol=1e-9)
    assert L.clean(L.reading([p]), _bin(p))


@settings(max_examples=300, deadline=None)
@given(layouts)
def test_a_clean_bin_is_one_of_the_objects_read_exactly(points: list[np.ndarray]) -> None:
    obs = L.reading(points)
    for b in range(LIDAR.bins):
        if not L.clean(obs, b):
            continue
        s = obs[b]
        after = obs[(b + 1) % LIDAR.bins]
        ang = (b + after / s) * LIDAR.width
        got = LIDAR.max_dist * (1 - s) * np.array([np.cos(ang), np.sin(ang)])
        assert min(np.linalg.norm(got - p) for p in points) < 1e-9


@settings(max_examples=300, deadline=None)
@given(layouts)
def test_a_centre_at_its_bins_floor_lies_within_its_arc(points: list[np.ndarray]) -> None:
    obs = L.reading(points)
    lo, hi = L.arcs(obs)
    start = np.arange(LIDAR.bins) * LIDAR.width
    assert np.all(start <= lo) and np.all(lo <= hi) and np.all(hi <= start + LIDAR.width)
    for p in points:
        b, d = _bin(p), float(np.hypot(*p))
        if d >= LIDAR.max_dist or abs((LIDAR.max_dist - d) / LIDAR.max_dist - obs[b]) > 1e-12:
            continue  # beyond the range, or not the one the bin's reading is
        ang = float(np.arctan2(p[1], p[0]) % (2 * np.pi))
        if b == 0 and ang > np.pi:  # on bin 0's start, as 2 pi
            ang -= 2 * np.pi
        assert lo[b] - 1e-9 <= ang <= hi[b] + 1e-9, (b, ang, lo[b], hi[b])
    # A single object's arc is its angle.
    one = points[0]
    if np.hypot(*one) < LIDAR.max_dist:
        b = _bin(one)
        lo1, hi1 = L.arcs(L.reading([one]))
        assert hi1[b] - lo1[b] < 1e-9


@settings(max_examples=500, deadline=None)
@given(
    st.floats(0.0, 0.1),  # delta
    st.floats(0.0, 1.0),  # how far the robot went, of delta
    st.floats(-np.pi, np.pi),  # which way
    st.floats(-1.0, 1.0),  # the point's direction off the centre's, of two bins
    st.floats(0.0, 2.0),  # the centre beyond the floor (m)
    st.sampled_from([0.3, 0.4]),  # the centre's kind's barrier radius (hazard, vase)
    st.floats(0.0, 2.5),  # the bin's clearance beyond the slack (m)
)
def test_the_slack_keeps_the_point_barrier_below_the_true_clearance(
    delta: float, went: float, way: float, off: float, beyond: float, r: float, gap: float
) -> None:
    from tlshield.envs.safety_gym.sensing import slack

    shared = 0.3
    s = slack(delta, shared)
    clearance = gap + s  # the barrier holds at the reading (D >= R + s)
    floor = clearance + r
    x = (floor + beyond) * np.array([1.0, 0.0])
    turn = off * 2 * LIDAR.width
    q = (clearance + shared - s) * np.array([np.cos(turn), np.sin(turn)])
    p = went * delta * np.array([np.cos(way), np.sin(way)])
    assert np.hypot(*(p - x)) - r >= np.hypot(*(p - q)) - shared - 1e-12
    # Half the slack does not hold in the worst case: the point two bins off the centre, the
    # robot moved along the difference of their directions (for any motion at all).
    if delta > 1e-3:
        u = np.array([np.cos(2 * LIDAR.width), np.sin(2 * LIDAR.width)])
        half = (clearance + shared - s / 2) * u
        worst = delta * (np.array([1.0, 0.0]) - u) / np.hypot(*(np.array([1.0, 0.0]) - u))
        x0 = floor * np.array([1.0, 0.0])
        assert np.hypot(*(worst - x0)) - r < np.hypot(*(worst - half)) - shared


def test_the_slack_is_infinite_once_the_motion_reaches_the_radius() -> None:
    from tlshield.envs.safety_gym.sensing import slack

    assert slack(0.0, 0.3) == 0.0
    assert slack(0.3, 0.3) == float("inf")
    # 1.5 m/s over Safety-Gymnasium's 0.02 s step: 2.6 cm, where twice the motion was 6 cm.
    assert 0.025 < slack(0.03 + 0.002, 0.3) < 0.027


@settings(max_examples=300, deadline=None)
@given(layouts, point, st.floats(0.0, 0.2))
def test_the_cover_stands_for_every_centre_up_to_twice_the_motion(
    points: list[np.ndarray], away: np.ndarray, delta: float
) -> None:
    centres, radii = L.cover(L.reading(points))
    robot = delta * away / np.hypot(*away)
    for p in points:
        b = _bin(p)
        to_disc = max(0.0, float(np.linalg.norm(robot - centres[b])) - radii[b])
        assert np.linalg.norm(robot - p) >= to_disc - 2 * delta - 1e-12
        if delta == 0.0:
            assert np.hypot(*p) >= to_disc - 1e-12


def test_bad_bins_are_refused_with_what_is_wrong() -> None:
    with pytest.raises(ValueError, match="expected 16 lidar bins"):
        L.floors(np.zeros(15))
    with pytest.raises(ValueError, match=r"must lie in \[0, 1\]"):
        L.cover(np.full(16, 1.5))
    with pytest.raises(ValueError, match=r"must lie in \[0, 1\]"):
        L.nearest(np.full(16, np.nan))
    with pytest.raises(ValueError, match="bins"):
        L.Lidar(bins=2)
    with pytest.raises(ValueError, match="max_dist"):
        L.Lidar(max_dist=0.0)


def test_nothing_seen_reads_none_and_floors_at_the_range() -> None:
    assert L.nearest(np.zeros(16)) is None
    np.testing.assert_array_equal(L.floors(np.zeros(16)), np.full(16, LIDAR.max_dist))


@settings(max_examples=200, deadline=None)
@given(layouts, st.floats(0.0, 1.0))
def test_each_disc_is_the_smallest_round_its_bins_arc(points: list[np.ndarray], t: float) -> None:
    obs = L.reading(points)
    centres, radii = L.cover(obs)
    floors = L.floors(obs)
    for b in range(LIDAR.bins):
        ang = (b + t) * LIDAR.width
        on_arc = floors[b] * np.array([np.cos(ang), np.sin(ang)])
        assert np.linalg.norm(on_arc - centres[b]) <= radii[b] + 1e-12
        # The arc's ends lie on the rim: no smaller disc holds the arc.
        end = floors[b] * np.array([np.cos(b * LIDAR.width), np.sin(b * LIDAR.width)])
        assert np.linalg.norm(end - centres[b]) == pytest.approx(radii[b], abs=1e-12)


def test_the_estimate_script_measures_bounds_that_hold(capsys: pytest.CaptureFixture) -> None:
    """``scripts/lidar_estimate.py`` on a tiny budget: its margins against MuJoCo's true
    positions are never negative (the floors, the cover and the shield's points hold), the
    goal and clean bins are read exactly, and it prints a table."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "scripts" / "lidar_estimate.py"
    spec = importlib.util.spec_from_file_location("lidar_estimate", path)
    assert spec is not None and spec.loader is not None
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    samples = script.measure("SafetyPointGoal2-v0", episodes=1, steps=30, seed=3)
    assert samples
    measured = {what for _, what, _ in samples}
    assert {"point margin", "point margin within delta"} <= measured
    for (kind, what, _band), xs in samples.items():
        if what in ("beyond floor", "beyond cover", "point margin", "point margin within delta"):
            assert min(xs) >= -1e-12, (kind, what)
        else:
            assert max(xs) < 1e-9, (kind, what)
    script.main(["--episodes", "1", "--steps", "5", "--tasks", "SafetyCarGoal1-v0"])
    assert "| hazards | beyond cover |" in capsys.readouterr().out
