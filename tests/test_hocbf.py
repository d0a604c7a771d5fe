"""Second-order barriers (HOCBF) and the second-order CLF under acceleration-level models,
against an independent solve: the rows written out by hand in numpy for a double integrator
and a ball obstacle, the QP solved by cvxpy."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import tlshield
from tests.shield_reference import CvxpyShield, Params, Rows, assert_matches

OBSTACLE, RADIUS = np.array([2.0, 0.1]), 0.5
GOAL = np.array([4.0, 0.0])
PARAMS = Params(alpha=1.5, c3=1.0, k=1e4, cbf=(-6.0, 6.0), clf=(-0.5, 0.5))
ALPHA2, CLF_GAIN = 2.0, 0.8


def make_shield(**overrides: object) -> tlshield.Shield:
    spec = tlshield.Spec("F g", {"g": tlshield.Ball(pos=[0, 1], radius=0.3, center=GOAL)})
    kwargs: dict[str, object] = {
        "alpha": PARAMS.alpha,
        "alpha2": ALPHA2,
        "c3": PARAMS.c3,
        "k": PARAMS.k,
        "cbf_bounds": PARAMS.cbf,
        "clf_bounds": PARAMS.clf,
        "clf_gain": CLF_GAIN,
        "barriers": {
            "!o": tlshield.Avoid(tlshield.Ball(pos=[0, 1], radius=RADIUS, center=OBSTACLE))
        },
        # The QP of Eq. 5D2 as hand_rows builds it (routing aims the CLF around the obstacle).
        "route": False,
        **overrides,
    }
    model = tlshield.DoubleIntegrator(pos=[0, 1], vel=[2, 3])
    return tlshield.Shield(spec, model, **kwargs)  # type: ignore[arg-type]


def hand_rows(s: np.ndarray, a_rl: np.ndarray) -> Rows:
    """The double integrator's rows by hand. Barrier h = |p - o| - r: psi_1 = u.v + alpha (h -
    margin), d psi_1/dt = (|v|^2 - (u.v)^2) / |p - o| + u.a + alpha u.v, so the row is
    u.(a_rl + a) + (|v|^2 - (u.v)^2)/d + alpha u.v + alpha2 psi_1 >= 0. CLF: e = v + k (p - g),
    V = |e|^2, dV/dt = 2 e.(a + k v)."""
    p, v = s[:2], s[2:]
    d = p - OBSTACLE
    dist = float(np.linalg.norm(d))
    u = d / dist
    h = dist - RADIUS
    psi = u @ v + PARAMS.alpha * (h - PARAMS.margin)
    lf_psi = (v @ v - (u @ v) ** 2) / dist + PARAMS.alpha * (u @ v)
    rhs = lf_psi + u @ a_rl + ALPHA2 * psi
    e = v + CLF_GAIN * (p - GOAL)
    clf_lg = 2.0 * e
    row_rhs = -(2.0 * e @ (CLF_GAIN * v) + clf_lg @ a_rl + PARAMS.c3 * (e @ e))
    lo, hi = PARAMS.clf
    delta_0 = max(float(np.minimum(clf_lg * lo, clf_lg * hi).sum()) - row_rhs, 0.0)
    return Rows(
        lg=u.reshape(1, 2),
        rhs=np.array([rhs]),
        clf_lg=clf_lg,
        clf_rhs=row_rhs + delta_0,
        delta_0=delta_0,
        has_goal=True,
    )


@pytest.fixture(scope="module")
def solvers() -> tuple[tlshield.Shield, CvxpyShield, CvxpyShield]:
    return make_shield(), CvxpyShield(PARAMS), CvxpyShield(PARAMS, relaxed=True)


def away(lo: float) -> st.SearchStrategy[np.ndarray]:
    """Positions at least ``lo`` from the obstacle's centre and outside the goal."""
    point = st.tuples(st.floats(-2.0, 6.0), st.floats(-3.0, 3.0)).map(np.array)
    return point.filter(
        lambda p: np.linalg.norm(p - OBSTACLE) > lo and np.linalg.norm(p - GOAL) > 0.35
    )


@settings(max_examples=2000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    p=away(0.05),
    v=st.tuples(st.floats(-3.0, 3.0), st.floats(-3.0, 3.0)).map(np.array),
    a_rl=st.tuples(st.floats(-4.0, 4.0), st.floats(-4.0, 4.0)).map(np.array),
)
def test_hocbf_equals_an_independent_solve(
    solvers: tuple[tlshield.Shield, CvxpyShield, CvxpyShield],
    p: np.ndarray,
    v: np.ndarray,
    a_rl: np.ndarray,
) -> None:
    shield, cvx, cvx_relaxed = solvers
    s = np.concatenate([p, v])
    got = shield.filter(s, 0, a_rl)
    assert_matches(got, hand_rows(s, a_rl), a_rl, (cvx, cvx_relaxed), 1e-6)
    np.testing.assert_allclose(got.goal, GOAL)


def test_first_order_models_are_unchanged_and_alpha2_is_required_where_needed() -> None:
    obstacle = {"!o": tlshield.Avoid(tlshield.Ball(pos=[0, 1], radius=RADIUS, center=OBSTACLE))}
    # A velocity-level model: the barrier has relative degree 1, alpha2 is not needed.
    spec = tlshield.Spec("F g", {"g": tlshield.Ball(pos=[0, 1], radius=0.3, center=GOAL)})
    gains = {"alpha": 1.0, "c3": 1.0, "k": 1e4, "cbf_bounds": (-6.0, 6.0)}
    model = tlshield.SingleIntegrator([0, 1])
    tlshield.Shield(spec, model, **gains, clf_bounds=(-1.0, 1.0), barriers=obstacle)
    with pytest.raises(tlshield.ShieldError, match=r"relative degree 2.*alpha2"):
        make_shield(alpha2=None)
    with pytest.raises(tlshield.ShieldError, match="alpha2"):
        make_shield(alpha2=-1.0)
    with pytest.raises(tlshield.ShieldError, match="clf_gain"):
        make_shield(clf_gain=0.0)
    with pytest.raises(ValueError, match="vel"):
        tlshield.DoubleIntegrator(pos=[0, 1], vel=[2])
    with pytest.raises(ValueError, match="distinct"):
        tlshield.AccelerationUnicycle(0, 1, 2, 2)


def test_models_step_as_documented() -> None:
    di = tlshield.DoubleIntegrator(pos=[0, 1], vel=[2, 3])
    np.testing.assert_allclose(
        di.step([1.0, 2.0, 0.5, -1.0], [2.0, 0.0], 0.1), [1.05, 1.9, 0.7, -1.0]
    )
    au = tlshield.AccelerationUnicycle()
    s = au.step([0.0, 0.0, np.pi / 2, 2.0], [1.0, 0.5], 0.1)
    np.testing.assert_allclose(s, [0.0, 0.2, np.pi / 2 + 0.05, 2.1], atol=1e-15)
    assert repr(di) == "DoubleIntegrator(pos=[0, 1], vel=[2, 3])"


def test_models_that_do_not_fit_are_clear_errors() -> None:
    # The spec's half-space fixes the state length at 3; the double integrator reads 4 values.
    spec = tlshield.Spec("F h", {"h": tlshield.Halfspace([1.0, 0.0, 0.0], 1.0)})
    model = tlshield.DoubleIntegrator(pos=[0, 1], vel=[2, 3])
    gains = {"alpha": 1.0, "alpha2": 1.0, "c3": 1.0, "k": 1e4}
    bounds = {"cbf_bounds": (-5.0, 5.0), "clf_bounds": (-1.0, 1.0)}
    with pytest.raises(tlshield.ShieldError, match="state length at 3"):
        tlshield.Shield(spec, model, **gains, **bounds)  # type: ignore[arg-type]
    # A barrier on dimensions no input reaches within two integrations.
    goal = tlshield.Spec("F g", {"g": tlshield.Ball(pos=[0, 1], radius=0.3, center=GOAL)})
    far = {"!far": tlshield.Avoid(tlshield.Ball(pos=[4, 5], radius=1.0, center=[0.0, 0.0]))}
    with pytest.raises(tlshield.ShieldError, match=r"relative degree > 2"):
        tlshield.Shield(goal, model, **gains, **bounds, barriers=far)  # type: ignore[arg-type]
