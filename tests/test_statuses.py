"""The rarer outcomes are produced and checked (issue 57, item 6): ``Status.INACCURATE`` (the
solver called a QP solved but its answer broke a row; the relaxed problem's checked answer is
returned instead) and ``GradFlag.SINGULAR`` (the active rows' KKT system is singular at working
precision; only the identity part of the gradient is returned). Both come from badly scaled
barriers, a wall whose gradient is 1e13-1e15, where a well-scaled copy of the same wall gives
SOLVED and an exact gradient."""

from __future__ import annotations

import numpy as np

import tlshield
from tlshield import GradFlag, Status

SPEC = tlshield.Spec("F g", {"g": tlshield.Ball([0, 1], 0.3, center=[5.0, 3.0])})
GAINS = {"alpha": 1.0, "c3": 1.0, "cbf_bounds": (-3.0, 3.0), "clf_bounds": (-1.0, 1.0)}


def wall(scale: float) -> tlshield.Inside:
    """x < 1, its robustness scaled by ``scale``."""
    return tlshield.Inside(tlshield.Halfspace([-scale, 0.0], scale))


def test_an_answer_outside_tolerance_is_inaccurate_and_the_returned_action_keeps_the_rows() -> None:
    floor = tlshield.Inside(tlshield.Halfspace([0.0, 1.0], 2.0))
    s = np.array([0.21819422112911013, 3.4817491719633615])
    a_rl = np.array([-1.9917726277415206, -1.3508506623907204])
    kw = {"k": 1e8, **GAINS}
    model = tlshield.SingleIntegrator([0, 1])
    steep = tlshield.Shield(
        SPEC, model, barriers={"wall": wall(1e15), "floor": floor}, solver="clarabel", **kw
    )
    out = steep.filter(s, 0, a_rl)
    assert out.status == Status.INACCURATE, out
    assert np.all(np.isfinite(out.action))
    # The action returned keeps every barrier row of the problem as posed, within the
    # tolerance a solved answer must meet (RESIDUAL_TOL = 1e-7 of the row's scale).
    qp = steep.problem(s, 0, a_rl)
    rows, m = 2, 2
    x = np.concatenate([out.a_cbf, out.a_clf])
    g, h = qp["G"][:rows, : 2 * m], qp["h"][:rows]
    scale = 1.0 + np.abs(h) + np.abs(g * x).sum(axis=1)
    assert np.all(g @ x - h <= 1e-7 * scale), (g @ x - h, scale)
    # The same wall, well scaled: solved as posed.
    plain = tlshield.Shield(
        SPEC, model, barriers={"wall": wall(1.0), "floor": floor}, solver="clarabel", **kw
    )
    assert plain.filter(s, 0, a_rl).status == Status.SOLVED


def test_a_singular_kkt_system_is_flagged_and_gives_the_identity_part_only() -> None:
    """At x = 0.999 pushed at the wall, the wall's row is active; scaled by 1e13 its KKT system
    is singular at working precision (pivot below 1e-13 of its largest entry)."""
    s, a_rl, v = np.array([[0.999, 0.0]]), np.array([[1.0, 0.0]]), np.array([[0.7, -0.4]])
    q = np.zeros(1, int)
    model = tlshield.SingleIntegrator([0, 1])
    steep = tlshield.Shield(SPEC, model, barriers={"wall": wall(1e13)}, k=10.0, **GAINS)
    ga, _, flags = steep.vjp_batch(s, q, a_rl, v, state_grad=False)
    assert flags[0] & GradFlag.SINGULAR
    assert steep.filter(s[0], 0, a_rl[0]).status == Status.SOLVED
    np.testing.assert_array_equal(ga, v)  # the identity part: through a_rl itself
    # Well scaled, the same step has an exact gradient: the wall stops a_rl's push in x.
    plain = tlshield.Shield(SPEC, model, barriers={"wall": wall(1.0)}, k=10.0, **GAINS)
    ga, _, flags = plain.vjp_batch(s, q, a_rl, v, state_grad=False)
    assert not flags[0] & GradFlag.SINGULAR
    eps = 1e-6
    fd = [
        (
            (plain.filter_batch(s, q, a_rl + d).action - plain.filter_batch(s, q, a_rl - d).action)
            @ v[0]
        )[0]
        / (2 * eps)
        for d in (np.array([[eps, 0.0]]), np.array([[0.0, eps]]))
    ]
    np.testing.assert_allclose(ga[0], fd, atol=1e-6)
    assert abs(ga[0, 0]) < 1e-6  # the push into the wall has no effect


def test_a_barrier_abeam_of_the_thrust_within_rounding_is_solved_as_if_exactly_abeam() -> None:
    # A ThrustTurn robot at rest, heading +x, an obstacle 2.6 m to its left: the barrier's
    # second-order row reads the thrust through grad h . heading, 0 exactly abeam and ~1e-16
    # when the obstacle's x is 1.6e-16 (a lidar bin's edge at 90 degrees). That row's plane
    # lies ~1e16 away; it used to set the active-set solver's scale and certify a point the
    # final check refused (INACCURATE on every step of such a reading).
    spec = tlshield.Spec(
        "(!h) U goal",
        {
            "goal": tlshield.Ball([0, 1], 0.25, center_dims=[5, 6]),
            "h": tlshield.Ball([0, 1], 0.36, center_dims=[7, 8]),
        },
    )
    shield = tlshield.Shield(
        spec.automaton(),
        tlshield.ThrustTurn(2.846, 1.0, 1.0),
        alpha=2.0,
        alpha2=4.0,
        c3=5.0,
        k=1e4,
        cbf_bounds=(-2.0, 2.0),
        clf_bounds=(-1.0, 1.0),
        action_bounds=((-1.0, -1.0), (1.0, 1.0)),
        disturbance={0: 0.05, 1: 0.05},
    )
    outs = [
        shield.filter(np.array([0, 0, 0, 0, 0, 1.0, 0.0, x, 2.609]), 0, np.zeros(2))
        for x in (0.0, 1.6e-16, -1.6e-16, 1e-12)
    ]
    for out in outs:
        assert out.status == Status.SOLVED, out
        np.testing.assert_allclose(out.action, outs[0].action, rtol=0, atol=1e-12)


def test_the_python_codes_are_the_cores_every_one() -> None:
    """``Status`` and ``Solver`` take their values from the core's tables, and every code the
    core has is a member (a new core status cannot come back as an unknown integer)."""
    from tlshield import Solver
    from tlshield._core import SOLVER_CODES, STATUS_CODES

    assert {s.name.lower(): int(s) for s in Status} == STATUS_CODES
    assert {s.name.lower(): int(s) for s in Solver} == SOLVER_CODES
    assert sorted(STATUS_CODES.values()) == list(range(len(STATUS_CODES)))
