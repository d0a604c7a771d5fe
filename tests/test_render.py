"""The channel renderer: frame shape and type, determinism (also across blitted frames),
sensitivity to the state, edge cases (short trajectories, goals off the arena), lazy import of
matplotlib, and show() without a display."""

from __future__ import annotations

import math
import subprocess
import sys
import warnings
from collections.abc import Iterator

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from tlshield.envs.render import ChannelRenderer, Scene

SCENE = Scene(half_width=1.5, goal_radius=0.5, obstacle_radius=0.3, arena=(-2.0, 11.0, -2.0, 11.0))
STATE = np.array(
    [1.5, 1.2, math.pi / 4, 3.5, 3.7, 4.2, 6.5, 8.0, 8.1, 5.5, 5.0, 6.8, 7.4], dtype=np.float64
)
TRAJ = np.array([[0.0, 0.0], [0.5, 0.3], [1.0, 0.7], [1.5, 1.2]])


@pytest.fixture(scope="module")
def renderer() -> Iterator[ChannelRenderer]:
    r = ChannelRenderer(SCENE, size=256)
    yield r
    r.close()


def test_frame_shape_and_dtype() -> None:
    r = ChannelRenderer(SCENE)
    frame = r.frame(STATE, TRAJ, 0, 3, title="rl_cbf_clf")
    assert frame.shape == (512, 512, 3)
    assert frame.dtype == np.uint8
    assert frame.flags.c_contiguous and frame.flags.writeable
    assert frame.min() < 50 and frame.max() == 255  # dark ink on a white figure
    r.close()


@pytest.mark.parametrize("size", [96, 300, 333])
def test_other_sizes(size: int) -> None:
    r = ChannelRenderer(SCENE, size=size)
    assert r.frame(STATE, TRAJ, 0, 0).shape == (size, size, 3)
    r.close()


def test_different_states_give_different_images(renderer: ChannelRenderer) -> None:
    a = renderer.frame(STATE, TRAJ, 0, 5)
    moved = STATE.copy()
    moved[0] += 1.0  # the agent
    assert not np.array_equal(a, renderer.frame(moved, TRAJ, 0, 5))
    turned = STATE.copy()
    turned[2] += math.pi / 2  # only the heading
    assert not np.array_equal(a, renderer.frame(turned, TRAJ, 0, 5))
    obstacle = STATE.copy()
    obstacle[9] -= 1.0
    assert not np.array_equal(a, renderer.frame(obstacle, TRAJ, 0, 5))
    # The text box: FSA state, step and title.
    assert not np.array_equal(a, renderer.frame(STATE, TRAJ, 1, 5))
    assert not np.array_equal(a, renderer.frame(STATE, TRAJ, 0, 6))
    assert not np.array_equal(a, renderer.frame(STATE, TRAJ, 0, 5, title="rl"))


def test_same_input_gives_identical_bytes(renderer: ChannelRenderer) -> None:
    a = renderer.frame(STATE, TRAJ, 2, 17, title="rl_cbf")
    # Other frames in between (other positions, a title change) leave nothing behind.
    other = STATE.copy()
    other[[0, 1, 3, 9]] += 2.0
    renderer.frame(other, np.vstack([TRAJ, [[4.0, 4.0]]]), 1, 18, title="rl")
    b = renderer.frame(STATE, TRAJ, 2, 17, title="rl_cbf")
    assert a.tobytes() == b.tobytes()
    # A fresh renderer of the same size agrees too.
    fresh = ChannelRenderer(SCENE, size=256)
    assert fresh.frame(STATE, TRAJ, 2, 17, title="rl_cbf").tobytes() == a.tobytes()
    fresh.close()


def test_frame_returns_a_copy(renderer: ChannelRenderer) -> None:
    a = renderer.frame(STATE, TRAJ, 0, 1)
    kept = a.copy()
    other = STATE.copy()
    other[0] = 8.0
    renderer.frame(other, TRAJ, 0, 2)
    assert np.array_equal(a, kept)


@pytest.mark.parametrize(
    "trajectory",
    [np.empty((0, 2)), np.array([]), [], np.array([[1.5, 1.2]]), [[0.0, 0.0], [1.5, 1.2]]],
)
def test_short_trajectories(renderer: ChannelRenderer, trajectory: object) -> None:
    frame = renderer.frame(STATE, trajectory, 0, 0)
    assert frame.shape == (256, 256, 3)


def test_empty_trajectory_draws_no_line(renderer: ChannelRenderer) -> None:
    empty = renderer.frame(STATE, np.empty((0, 2)), 0, 0)
    line = renderer.frame(STATE, np.array([[-1.0, -1.5], [1.5, 1.2]]), 0, 0)
    assert not np.array_equal(empty, line)


def test_goals_and_obstacles_outside_the_arena(renderer: ChannelRenderer) -> None:
    s = STATE.copy()
    s[3:5] = (50.0, 50.0)
    s[5:7] = (-1e6, 3.0)
    s[7:9] = (10.9, 11.2)  # partly inside
    s[9:11] = (-40.0, 12.0)
    s[0:2] = (30.0, -30.0)  # even the agent
    frame = renderer.frame(s, np.array([[0.0, 0.0], [30.0, -30.0]]), 0, 1)
    assert frame.shape == (256, 256, 3)
    # Far-away objects are clipped away: moving them further changes nothing.
    s[3:5] = (80.0, 80.0)
    s[9:11] = (-60.0, 20.0)
    assert np.array_equal(frame, renderer.frame(s, np.array([[0.0, 0.0], [30.0, -30.0]]), 0, 1))


def test_bad_input() -> None:
    r = ChannelRenderer(SCENE, size=128)
    with pytest.raises(ValueError, match="state"):
        r.frame(STATE[:5], TRAJ, 0, 0)
    with pytest.raises(ValueError, match="trajectory"):
        r.frame(STATE, np.zeros((4, 3)), 0, 0)
    with pytest.raises(ValueError, match="arena"):
        ChannelRenderer(Scene(1.5, 0.5, 0.3, (1.0, 0.0, 0.0, 1.0)))
    with pytest.raises(ValueError, match="positive"):
        ChannelRenderer(Scene(0.0, 0.5, 0.3, (0.0, 1.0, 0.0, 1.0)))
    r.close()


def test_close_then_frame_rebuilds() -> None:
    r = ChannelRenderer(SCENE, size=128)
    a = r.frame(STATE, TRAJ, 0, 1)
    r.close()
    r.close()  # idempotent
    assert r.frame(STATE, TRAJ, 0, 1).tobytes() == a.tobytes()
    r.close()


def test_import_does_not_need_matplotlib() -> None:
    code = (
        "import sys; import tlshield.envs.render as r; "
        "r.ChannelRenderer(r.Scene(1.5, 0.5, 0.3, (-2, 11, -2, 11))); "
        "assert 'matplotlib' not in sys.modules, 'matplotlib imported'"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_show_without_a_display_warns_once(monkeypatch: pytest.MonkeyPatch) -> None:
    import matplotlib

    monkeypatch.setenv("MPLBACKEND", "Agg")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setitem(matplotlib.rcParams, "backend", "Agg")
    r = ChannelRenderer(SCENE, size=128)
    frame = r.frame(STATE, TRAJ, 0, 0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r.show(frame)
        r.show(frame)
    assert len(caught) == 1, [str(w.message) for w in caught]
    assert issubclass(caught[0].category, RuntimeWarning)
    assert "cannot display" in str(caught[0].message)
    r.close()


def test_env_renders_through_the_renderer() -> None:
    import gymnasium as gym

    from tlshield.envs import ENV_ID

    env = gym.make(ENV_ID, render_mode="rgb_array")
    env.reset(seed=0)
    first = env.render()
    env.step(np.zeros(2))
    second = env.render()
    assert isinstance(first, np.ndarray) and isinstance(second, np.ndarray)
    assert first.shape == second.shape == (512, 512, 3)
    assert not np.array_equal(first, second)  # step counter (and the agent) moved
    env.close()
