"""Barriers on points of the robot's body (``Ball(heading=..., offset=...)``): the predicate
against the point worked out by hand, and the shield's two rows for a body point under the
acceleration unicycle (mixed relative degree) against an independent solve: the rows written
out in numpy, ``grad psi_1`` by finite differences, the QP solved by cvxpy."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import tlshield
from tests.shield_reference import CvxpyShield, Params, Rows, assert_matches

OBSTACLE, RADIUS, AHEAD = np.array([2.0, 0.1]), 0.5, 0.8
PARAMS = Params(alpha=1.5, cbf=(-6.0, 6.0), margin=1e-6)
ALPHA2 = 2.0


def body_point(s: np.ndarray) -> np.ndarray:
    return s[:2] + AHEAD * np.array([math.cos(s[2]), math.sin(s[2])])


def test_the_ball_holds_the_body_point() -> None:
    ball = tlshield.Ball(pos=[0, 1], radius=1.0, center=[0, 0], heading=2, offset=(0.8, 0.3))
    rng = np.random.default_rng(0)
    for s in rng.uniform(-3, 3, (50, 3)):
        c, sn = math.cos(s[2]), math.sin(s[2])
        q = s[:2] + np.array([0.8 * c - 0.3 * sn, 0.8 * sn + 0.3 * c])
        assert ball.robustness(s) == pytest.approx(1.0 - np.linalg.norm(q), abs=1e-12)
        fd = [(ball.robustness(s + e) - ball.robustness(s - e)) / 2e-6 for e in 1e-6 * np.eye(3)]
        np.testing.assert_allclose(ball.gradient(s), fd, atol=1e-6)
    assert (ball.heading, ball.offset) == (2, (0.8, 0.3))
    copy = pickle.loads(pickle.dumps(ball))
    assert repr(copy) == repr(ball)
    assert "heading=2, offset=(0.8, 0.3)" in repr(ball)
    plain = tlshield.Ball(pos=[0, 1], radius=1.0, center=[0, 0])
    assert (plain.heading, plain.offset) == (None, None)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"heading": 2}, "heading and offset together"),
        ({"offset": (1.0, 0.0)}, "heading and offset together"),
        ({"heading": 0, "offset": (1.0, 0.0)}, "heading dimension 0"),
        ({"heading": 2, "offset": (1.0,)}, "expected 2 values"),
        ({"heading": 2, "offset": (1.0, float("nan"))}, "offset"),
    ],
)
def test_bad_body_points_are_clear_errors(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        tlshield.Ball(pos=[0, 1], radius=1.0, center=[0, 0], **kwargs)  # type: ignore[arg-type]


def make_shield() -> tlshield.Shield:
    spec = tlshield.Spec("F g", {"g": tlshield.Ball(pos=[0, 1], radius=0.3, center=[9, 9])})
    obstacle = tlshield.Ball(
        pos=[0, 1], radius=RADIUS, center=OBSTACLE, heading=2, offset=(AHEAD, 0.0)
    )
    return tlshield.Shield(
        spec,
        tlshield.AccelerationUnicycle(x=0, y=1, theta=2, v=3),
        alpha=PARAMS.alpha,
        alpha2=ALPHA2,
        c3=PARAMS.c3,
        k=PARAMS.k,
        cbf_bounds=PARAMS.cbf,
        clf_bounds=PARAMS.clf,
        margin=PARAMS.margin,
        use_clf=False,
        barriers={"!o": tlshield.Avoid(obstacle)},
    )


def hand_rows(s: np.ndarray, a_rl: np.ndarray) -> Rows:
    """h = |q - o| - r at the body point q = p + l (cos, sin)(theta). Without input q moves at
    v along the heading, so Lf h = u . v dir and psi_1 = Lf h + alpha (h - margin); the turn
    rate moves q by l omega dir_perp, so Lg h = (0, u . l dir_perp). Row A: grad psi_1 . (f +
    g (a_rl + a)) + alpha2 psi_1 >= 0; row B: Lg h . (a_rl + a) + alpha (h - margin) >= 0."""

    def parts(s: np.ndarray) -> tuple[float, float, np.ndarray]:
        d = body_point(s) - OBSTACLE
        u = d / np.linalg.norm(d)
        heading = np.array([math.cos(s[2]), math.sin(s[2])])
        h = float(np.linalg.norm(d)) - RADIUS
        psi = float(u @ (s[3] * heading)) + PARAMS.alpha * (h - PARAMS.margin)
        return h, psi, u

    h, psi, u = parts(s)
    grad_psi = np.array([(parts(s + e)[1] - parts(s - e)[1]) / 2e-7 for e in 1e-7 * np.eye(4)])
    f = np.array([s[3] * math.cos(s[2]), s[3] * math.sin(s[2]), 0.0, 0.0])
    g = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 1.0], [1.0, 0.0]])
    lg_a = grad_psi @ g
    perp = np.array([-math.sin(s[2]), math.cos(s[2])])
    lg_b = np.array([0.0, AHEAD * float(u @ perp)])
    return Rows(
        lg=np.stack([lg_a, lg_b]),
        rhs=np.array(
            [
                grad_psi @ f + lg_a @ a_rl + ALPHA2 * psi,
                lg_b @ a_rl + PARAMS.alpha * (h - PARAMS.margin),
            ]
        ),
        clf_lg=np.zeros(2),
        clf_rhs=0.0,
        delta_0=0.0,
        has_goal=False,
    )


@pytest.fixture(scope="module")
def solvers() -> tuple[tlshield.Shield, CvxpyShield, CvxpyShield]:
    return make_shield(), CvxpyShield(PARAMS), CvxpyShield(PARAMS, relaxed=True)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    s=st.tuples(
        st.floats(-2.0, 6.0), st.floats(-3.0, 3.0), st.floats(-math.pi, math.pi), st.floats(0, 2)
    ).map(np.array),
    a_rl=st.tuples(st.floats(-4.0, 4.0), st.floats(-4.0, 4.0)).map(np.array),
)
def test_body_point_rows_equal_an_independent_solve(
    solvers: tuple[tlshield.Shield, CvxpyShield, CvxpyShield],
    s: np.ndarray,
    a_rl: np.ndarray,
) -> None:
    shield, cvx, cvx_relaxed = solvers
    if np.linalg.norm(body_point(s) - OBSTACLE) < RADIUS + 0.05:
        return
    got = shield.filter(s, 0, a_rl)
    assert_matches(got, hand_rows(s, a_rl), a_rl, (cvx, cvx_relaxed), 1e-5)
