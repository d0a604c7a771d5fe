"""The shield checks the state's layout against its model's (issue 57, slips 2 and 3): the CLF
drives the model's own position unless told otherwise, and a position, a ball, a centre read
from the state or a drift that contradicts which dimensions the model's inputs move is a
ShieldError that names the dimensions, at construction (the drift: at the call that passes
it). The warehouse of the issue: the robot ``(x, y)``, a forklift's centre ``(fx, fy)``, the
heading ``theta``."""

from __future__ import annotations

import numpy as np
import pytest

import tlshield

GAINS = {"alpha": 2.0, "c3": 1.0, "k": 1e4, "cbf_bounds": (-4.0, 4.0), "clf_bounds": (-1.0, 1.0)}


def goal_spec(pos: list[int], centre: list[float]) -> tlshield.Spec:
    return tlshield.Spec("F g", {"g": tlshield.Ball(pos, 0.3, center=centre)})


def test_a_robot_at_other_dims_is_driven_by_its_own_position() -> None:
    # The issue: Unicycle(x=2, y=3, theta=4) without pos= had the CLF drive dims (0, 1) (a
    # forklift's) and the robot never moved. The CLF's position is now the model's.
    model = tlshield.Unicycle(0.1, x=2, y=3, theta=4)
    sh = tlshield.Shield(goal_spec([2, 3], [3.0, 0.0]), model, **GAINS)
    assert "pos=[2, 3]" in repr(sh)
    s = np.array([7.0, 7.0, 0.0, 0.0, 0.0])  # the robot at (0, 0) facing the goal at (3, 0)
    out = sh.filter(s, 0, [0.0, 0.0])
    assert out.a_clf[0] > 0.1  # the shield alone pushes the robot towards the goal
    # Stepping it moves dims 2-3 towards the goal and leaves 0-1 alone.
    for _ in range(200):
        s = model.step(s, sh.filter(s, 0, [0.0, 0.0]).action, 0.05)
    assert np.hypot(s[2] - 3.0, s[3]) < 0.3 and s[0] == s[1] == 7.0


def test_a_pos_or_a_goal_over_dims_the_model_does_not_move_is_refused() -> None:
    model = tlshield.Unicycle(0.1, x=2, y=3, theta=4)
    with pytest.raises(tlshield.ShieldError, match=r"pos = \[0, 1\].*\[0, 1\].*does not move"):
        tlshield.Shield(goal_spec([2, 3], [3.0, 0.0]), model, pos=[0, 1], **GAINS)
    # A goal ball over the forklift's dims: the robot can never enter it.
    with pytest.raises(tlshield.ShieldError, match=r'atom "g": a ball over dimensions \[0, 1\]'):
        tlshield.Shield(goal_spec([0, 1], [3.0, 0.0]), model, **GAINS)


def test_a_centre_read_from_dims_an_input_moves_is_refused() -> None:
    # The issue: a state (x, y, fx, fy, theta) under Unicycle(eps=0.1)'s default dims
    # (theta = 2, the forklift's x). The forklift's disc reads its centre from dims 2-3.
    forklift = tlshield.Avoid(tlshield.Ball([0, 1], 0.5, center_dims=[2, 3]))
    spec = goal_spec([0, 1], [3.0, 0.0])
    with pytest.raises(tlshield.ShieldError, match=r"centre is read from dimensions \[2, 3\]"):
        tlshield.Shield(spec, tlshield.Unicycle(0.1), barriers={"forklift": forklift}, **GAINS)
    # The layout stated: accepted, and the forklift's centre is read from 2-3.
    model = tlshield.Unicycle(0.1, x=0, y=1, theta=4)
    sh = tlshield.Shield(spec, model, barriers={"forklift": forklift}, **GAINS)
    s = np.array([0.0, 0.0, 1.5, 0.0, 0.0])
    assert dict(sh.filter(s, 0, [0.0, 0.0]).barriers)["forklift"] == pytest.approx(1.0)


def test_a_drift_on_a_dimension_an_input_moves_is_refused_at_the_call() -> None:
    forklift = tlshield.Avoid(tlshield.Ball([0, 1], 0.5, center_dims=[2, 3]))
    model = tlshield.Unicycle(0.1, x=0, y=1, theta=4)
    sh = tlshield.Shield(
        goal_spec([0, 1], [3.0, 0.0]), model, barriers={"forklift": forklift}, **GAINS
    )
    s = np.array([0.0, 0.0, 1.5, 0.0, 0.0])
    moving = np.array([0.0, 0.0, -0.5, 0.0, 0.0])  # the forklift's measured velocity
    assert sh.filter(s, 0, [0.0, 0.0], drift=moving).status == tlshield.Status.SOLVED
    with pytest.raises(tlshield.ShieldError, match=r"drift\[4\] = 0.2: dimension 4 is one"):
        sh.filter(s, 0, [0.0, 0.0], drift=np.array([0.0, 0.0, -0.5, 0.0, 0.2]))
    with pytest.raises(tlshield.ShieldError, match=r"drift\[0\]"):
        sh.filter_batch(
            np.stack([s, s]), [0, 0], np.zeros((2, 2)), drift=np.array([moving, [1.0, 0, 0, 0, 0]])
        )
