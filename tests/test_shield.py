"""The shield from Python: against an independent cvxpy solve of the same QP, the paper's
configurations, batches, and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import tlshield
from tests.fixtures import PARAMS, task_shield
from tests.shield_reference import (
    ClarabelShield,
    CvxpyShield,
    Structure,
    Task,
    assert_matches,
    build_rows,
)
from tlshield import Solver, Status
from tlshield.envs.channel import STATE_DIM, channel_task_spec

TASK = Task()


def make_shield(**overrides: object) -> tlshield.Shield:
    return task_shield(**overrides)


def state(x: float, offset: float, theta: float, goals: np.ndarray | None = None) -> np.ndarray:
    """Reference point at distance ``offset`` across the channel's diagonal, goals given or
    the defaults (g1, g2 ahead in the channel, g3 far along it), obstacles far away."""
    s = np.zeros(STATE_DIM)
    s[0], s[1], s[2] = x + offset / 2, x - offset / 2, theta
    s[3:9] = goals if goals is not None else [4.0, 4.0, 4.5, 6.5, 9.0, 9.0]
    s[9:13] = [20.0, 20.0, 20.0, -20.0]
    return s


@pytest.fixture(scope="module")
def shield() -> tlshield.Shield:
    return make_shield()


@pytest.fixture(scope="module")
def reference(shield: tlshield.Shield) -> tuple[Structure, CvxpyShield, CvxpyShield]:
    return Structure(shield.automaton), CvxpyShield(PARAMS), CvxpyShield(PARAMS, relaxed=True)


instances = st.builds(
    lambda x, offset, theta, v, w, goals: (state(x, offset, theta, np.array(goals)), v, w),
    st.floats(-1.0, 10.0),
    # Inside the channel (|offset| < 1.5), on its border, and a little outside.
    st.one_of(st.floats(-1.6, 1.6), st.sampled_from([-1.5, 1.5, -1.4999, 1.4999])),
    st.floats(-math.pi, math.pi),
    st.floats(-4.0, 4.0),
    st.floats(-6.0, 6.0),
    st.lists(st.floats(-1.0, 10.0), min_size=6, max_size=6),
)


@settings(max_examples=2000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(instance=instances, q0=st.sampled_from([0, 3]))
def test_equals_an_independent_cvxpy_solve(
    shield: tlshield.Shield,
    reference: tuple[Structure, CvxpyShield, CvxpyShield],
    instance: tuple[np.ndarray, float, float],
    q0: int,
) -> None:
    """Thousands of random steps (feasible, on the boundary, outside the channel): the action
    equals cvxpy's solve of the same QP within 1e-5, and delta = 0 whenever the CLF row alone
    can hold within the CLF bounds."""
    structure, cvx, cvx_relaxed = reference
    s, v, w = instance
    q = shield.automaton.step(s, q0)
    a_rl = np.array([v, w])
    got = shield.filter(s, q, a_rl)
    rows = build_rows(TASK, structure, PARAMS, s, q, a_rl)
    assert_matches(got, rows, a_rl, (cvx, cvx_relaxed), 1e-5)
    if rows.delta_0 == 0.0 and got.status == Status.SOLVED:
        assert got.delta <= 1e-9, got


def test_clarabel_python_baseline_agrees(
    shield: tlshield.Shield, reference: tuple[Structure, CvxpyShield, CvxpyShield]
) -> None:
    """The benchmark's clarabel-python baseline solves the same QP (checked so its timings
    compare like with like)."""
    structure = reference[0]
    baseline = ClarabelShield(PARAMS)
    rng = np.random.default_rng(3)
    stalled = 0
    for _ in range(300):
        s = state(rng.uniform(0, 8), rng.uniform(-1.4, 1.4), rng.uniform(-3, 3))
        q = shield.automaton.step(s, 0)
        a_rl = rng.uniform([-4, -6], [4, 6])
        rows = build_rows(TASK, structure, PARAMS, s, q, a_rl)
        want = baseline.solve(rows)
        if want is None:
            # clarabel-python at 1e-10 tolerances can stall (MaxIterations): cvxpy then checks
            # the step, and stalls stay rare.
            stalled += 1
            want = reference[1].solve(rows)
            assert want is not None
        np.testing.assert_allclose(
            shield.filter(s, q, a_rl).action, a_rl + want[0] + want[1], atol=1e-5
        )
    assert stalled <= 3


def test_border_step_is_corrected_and_reported(shield: tlshield.Shield) -> None:
    s = state(1.0, -1.4, math.pi / 2)  # near c1's wall, heading out
    q = shield.automaton.step(s, 0)
    out = shield.filter(s, q, [3.0, 0.0])
    assert out.status == Status.SOLVED and out.solver == Solver.ACTIVE_SET
    names = [name for name, _ in out.barriers]
    assert "c1" in names and "c2" in names
    h_c1 = dict(out.barriers)["c1"]
    assert h_c1 == pytest.approx(s[0] - s[1] + 1.5)
    assert out.a_cbf[0] < -0.5  # slows down
    assert out.goal is not None and out.goal.shape == (2,)
    np.testing.assert_allclose(out.action, np.array([3.0, 0.0]) + out.a_cbf + out.a_clf)
    assert "FilterResult" in repr(out)


@pytest.mark.parametrize("solver", ["auto", "clarabel", "active_set"])
def test_solver_choice_is_honoured(solver: str) -> None:
    sh = make_shield(solver=solver)
    s = state(1.0, -1.4, math.pi / 2)
    out = sh.filter(s, sh.automaton.step(s, 0), [3.0, 0.0])
    assert str(out.solver) == {"auto": "active_set"}.get(solver, solver)
    reference = make_shield(solver="clarabel").filter(s, 0, [3.0, 0.0])
    np.testing.assert_allclose(out.action, reference.action, atol=1e-6)


def test_configurations() -> None:
    s = state(2.0, 0.3, 0.4)
    a = np.array([0.5, 0.1])
    off = make_shield(use_cbf=False, use_clf=False).filter(s, 0, a)
    assert off.solver == Solver.NONE and np.array_equal(off.action, a) and off.barriers == []
    clf_only = make_shield(use_cbf=False).filter(s, 0, a)
    assert np.all(clf_only.a_cbf == 0) and clf_only.goal is not None
    cbf_only = make_shield(use_clf=False).filter(s, 0, a)
    assert np.all(cbf_only.a_clf == 0) and cbf_only.goal is None and cbf_only.delta == 0


def test_infeasible_is_relaxed_with_slack_never_nan() -> None:
    sh = make_shield(cbf_bounds=(-0.01, 0.01), clf_bounds=(-0.01, 0.01))
    s = state(1.0, -2.0, math.pi / 2)  # outside the channel, heading further out
    out = sh.filter(s, 0, [5.0, 0.0])
    assert out.status == Status.RELAXED and out.slack > 0
    assert np.all(np.isfinite(out.action))


def test_user_barriers_and_per_call_dynamics() -> None:
    wall = tlshield.Halfspace([0.0, -1.0] + [0.0] * 11, 3.0)  # y < 3
    sh = make_shield(barriers={"wall": tlshield.Inside(wall)})
    s = state(2.9, 0.0, math.pi / 2)
    out = sh.filter(s, 0, [2.0, 0.0])
    assert dict(out.barriers)["wall"] == pytest.approx(3.0 - s[1])
    f, g = tlshield.Unicycle(0.1).eval(s)
    again = sh.filter(s, 0, [2.0, 0.0], f=f, g=g)
    np.testing.assert_array_equal(out.action, again.action)
    positional = make_shield(barriers=[tlshield.Inside(wall)]).filter(s, 0, [2.0, 0.0])
    assert dict(positional.barriers)["h0"] == pytest.approx(3.0 - s[1])
    no_model = tlshield.Shield(
        channel_task_spec(),
        None,
        alpha=2.0,
        c3=1.0,
        k=1e4,
        cbf_bounds=([-6, -6], [6, 6]),
        clf_bounds=(-0.5, 0.5),
    )
    np.testing.assert_allclose(
        no_model.filter(s, 0, [2.0, 0.0], f=f, g=g).action,
        make_shield().filter(s, 0, [2.0, 0.0]).action,
    )


def test_single_integrator_keeps_a_disc_invariant() -> None:
    spec = tlshield.Spec("F goal", {"goal": tlshield.Ball([0, 1], 0.2, center=[3.0, 0.0])})
    arena = tlshield.Ball([0, 1], 4.0, center=[0.0, 0.0])
    sh = tlshield.Shield(
        spec,
        tlshield.SingleIntegrator([0, 1]),
        alpha=5.0,
        c3=1.0,
        k=1e4,
        cbf_bounds=(-10, 10),
        clf_bounds=(-1, 1),
        barriers=[tlshield.Inside(arena)],
    )
    p = np.array([0.0, 3.5])
    rng = np.random.default_rng(0)
    for _ in range(400):
        out = sh.filter(p, 0, rng.uniform(-3, 3, size=2))
        p = p + 0.02 * out.action
        assert arena.robustness(p) >= -1e-9


def test_batch_equals_single_calls(shield: tlshield.Shield) -> None:
    rng = np.random.default_rng(11)
    states = np.stack(
        [state(rng.uniform(0, 8), rng.uniform(-1.6, 1.6), rng.uniform(-3, 3)) for _ in range(64)]
    )
    qs = np.array([shield.automaton.step(s, 0) for s in states])
    a_rl = rng.uniform([-4, -6], [4, 6], size=(64, 2))
    batch = shield.filter_batch(states, qs, a_rl)
    assert isinstance(batch, tlshield.FilterBatch) and len(batch) == 64
    assert batch.action.shape == (64, 2) and batch.status.dtype == np.uint8
    for i in range(64):
        single = shield.filter(states[i], int(qs[i]), a_rl[i])
        np.testing.assert_array_equal(batch.action[i], single.action)
        np.testing.assert_array_equal(batch.a_cbf[i], single.a_cbf)
        assert batch.delta[i] == single.delta and batch.slack[i] == single.slack
        # One encoding: the batch's codes are the single call's enum members.
        assert batch.status[i] == single.status and Status(batch.status[i]) is single.status
        assert Solver(batch.solver[i]) is single.solver
    # Non-contiguous and integer input is accepted.
    again = shield.filter_batch(states[::2], qs[::2].astype(np.int32), a_rl[::2])
    np.testing.assert_array_equal(again.action, batch.action[::2])


def test_same_input_same_output(shield: tlshield.Shield) -> None:
    s = state(3.0, 1.2, 2.0)
    first = shield.filter(s, 0, [1.0, -1.0])
    assert all(
        np.array_equal(shield.filter(s, 0, [1.0, -1.0]).action, first.action) for _ in range(20)
    )


BAD_CONSTRUCTION = [
    ({"alpha": 0.0}, ValueError, "alpha"),
    ({"alpha": float("nan")}, ValueError, "alpha"),
    ({"k": -1.0}, ValueError, "k"),
    ({"cbf_bounds": (1.0, -1.0)}, ValueError, "lower bound above upper"),
    ({"cbf_bounds": ([0.0], [1.0])}, ValueError, "cbf_bounds"),
    ({"clf_bounds": (0.0, float("inf"))}, ValueError, "finite"),
    ({"clf_bounds": "wide"}, TypeError, "clf_bounds"),
    ({"action_bounds": (2.0, 1.0)}, ValueError, "action_bounds"),
    ({"solver": "osqp"}, ValueError, "solver"),
    ({"pos": [0, 0]}, ValueError, "pos"),
    ({"pos": [0, 1, 2]}, ValueError, "pos"),
    ({"pos": [-1, 1]}, ValueError, "pos"),
    ({"barriers": [1.0]}, TypeError, "Avoid"),
    ({"barriers": 3}, TypeError, "barriers"),
]


@pytest.mark.parametrize(("overrides", "error", "fragment"), BAD_CONSTRUCTION)
def test_bad_construction(overrides: dict[str, object], error: type, fragment: str) -> None:
    with pytest.raises(error, match=fragment):
        make_shield(**overrides)


def test_bad_spec_or_dynamics() -> None:
    with pytest.raises(TypeError, match="Spec"):
        tlshield.Shield(
            "F a",
            tlshield.Unicycle(0.1),
            alpha=1,
            c3=1,
            k=1,
            cbf_bounds=(-1, 1),
            clf_bounds=(-1, 1),
        )
    with pytest.raises(TypeError, match="dynamics"):
        tlshield.Shield(
            channel_task_spec(),
            "unicycle",
            alpha=1,
            c3=1,
            k=1,
            cbf_bounds=(-1, 1),
            clf_bounds=(-1, 1),
        )
    with pytest.raises(ValueError, match="eps"):
        tlshield.Unicycle(0.0)
    with pytest.raises(ValueError, match="SingleIntegrator pos"):
        tlshield.SingleIntegrator([])


BAD_CALLS = [
    (lambda s: (s[:5], 0, [0.0, 0.0]), "length"),
    (lambda s: (s, 7, [0.0, 0.0]), "state 7"),
    (lambda s: (s, -1, [0.0, 0.0]), "state -1"),
    (lambda s: (s, 0, [0.0]), "a_rl"),
    (lambda s: (s, 0, [float("nan"), 0.0]), "a_rl"),
    (lambda s: (np.where(np.arange(13) == 4, np.inf, s), 0, [0.0, 0.0]), "finite"),
    (lambda s: (s, 0, [[0.0, 0.0]]), "a_rl"),
]


@pytest.mark.parametrize(("args", "fragment"), BAD_CALLS)
def test_bad_calls(shield: tlshield.Shield, args: object, fragment: str) -> None:
    with pytest.raises(ValueError, match=fragment):
        shield.filter(*args(state(1.0, 0.0, 0.0)))  # type: ignore[operator]


def test_bad_call_types_and_dynamics(shield: tlshield.Shield) -> None:
    s = state(1.0, 0.0, 0.0)
    with pytest.raises(TypeError, match="s: expected an array-like of numbers"):
        shield.filter(None, 0, [0.0, 0.0])
    with pytest.raises(TypeError, match="s: expected real numbers"):
        shield.filter(["a"] * 13, 0, [0.0, 0.0])
    f, g = tlshield.Unicycle(0.1).eval(s)
    with pytest.raises(ValueError, match="both f and g"):
        shield.filter(s, 0, [0.0, 0.0], f=f)
    with pytest.raises(ValueError, match="g"):
        shield.filter(s, 0, [0.0, 0.0], f=f, g=g[:, :1])
    with pytest.raises(ValueError, match="f"):
        shield.filter(s, 0, [0.0, 0.0], f=f[:3], g=g)
    with pytest.raises(ValueError, match="g"):
        shield.filter(s, 0, [0.0, 0.0], f=f, g=np.full_like(g, np.nan))


def test_bad_batches(shield: tlshield.Shield) -> None:
    states = np.stack([state(1.0, 0.0, 0.0)] * 4)
    with pytest.raises(ValueError, match="qs"):
        shield.filter_batch(states, [0, 0, 0], np.zeros((4, 2)))
    with pytest.raises(ValueError, match="a_rl"):
        shield.filter_batch(states, [0, 0, 0, 0], np.zeros((4, 3)))
    with pytest.raises(ValueError, match=r"qs\[2\]"):
        shield.filter_batch(states, [0, 0, 9, 0], np.zeros((4, 2)))
    bad = states.copy()
    bad[1, 0] = np.nan
    with pytest.raises(ValueError, match="states"):
        shield.filter_batch(bad, [0, 0, 0, 0], np.zeros((4, 2)))
    with pytest.raises(ValueError, match="states"):
        shield.filter_batch(states[0], [0], np.zeros((1, 2)))


def test_automaton_goal_from_python(shield: tlshield.Shield) -> None:
    aut = shield.automaton
    s = state(3.9, 0.0, 0.0)  # next to g1 (4, 4)
    np.testing.assert_allclose(aut.goal(s, 0), [4.0, 4.0])
    assert aut.goal(s, aut.accepting[0]) is None
    with pytest.raises(ValueError, match="state 99"):
        aut.goal(s, 99)
    with pytest.raises(ValueError, match="state length: expected 13, got 4"):
        aut.goal(s[:4], 0)


def obstacle_shield() -> tlshield.Shield:
    """The channel shield with obstacle 1 as an outside barrier (``"!o1"``)."""
    ball = tlshield.Ball([0, 1], 0.5, center_dims=[9, 10])
    return make_shield(barriers={"!o1": tlshield.Avoid(ball)}, use_clf=False)


def test_outside_barrier_and_drift_match_an_explicit_f() -> None:
    sh = obstacle_shield()
    s = state(2.0, 0.0, math.pi / 4)
    s[9:11] = [3.0, 3.0]  # 1.41 m ahead on the centre line
    a_rl = np.array([1.0, 0.0])
    drift = np.zeros(STATE_DIM)
    drift[9:11] = [-1.0, -1.0]  # coming straight at the agent at 1.4 m/s
    out = sh.filter(s, 0, a_rl, drift=drift)
    h = dict(out.barriers)["!o1"]
    assert h == pytest.approx(math.hypot(1.0, 1.0) - 0.5)
    f, g = tlshield.Unicycle(0.1).eval(s)
    explicit = sh.filter(s, 0, a_rl, f=f + drift, g=g)
    np.testing.assert_array_equal(out.action, explicit.action)
    # The row: d/dt |p - o| = u . (p_dot - o_dot) >= -alpha (h - margin). Without the drift
    # the shield would let the agent drive on at full speed; with it, it brakes.
    still = sh.filter(s, 0, a_rl)
    assert still.action[0] > out.action[0] + 0.1
    u = (s[:2] - s[9:11]) / np.linalg.norm(s[:2] - s[9:11])
    p_dot = g[:2] @ out.action
    assert u @ (p_dot - drift[9:11]) >= -PARAMS.alpha * (h - 1e-6) - 1e-7
    batch = sh.filter_batch(
        np.stack([s, s]), [0, 0], np.stack([a_rl, a_rl]), np.stack([drift, drift])
    )
    np.testing.assert_array_equal(batch.action[1], out.action)


def test_bad_drift_is_a_clear_error() -> None:
    sh = obstacle_shield()
    s = state(2.0, 0.0, 0.5)
    with pytest.raises(ValueError, match="drift"):
        sh.filter(s, 0, np.zeros(2), drift=np.zeros(3))
    with pytest.raises(ValueError, match="drift"):
        sh.filter(s, 0, np.zeros(2), drift=np.full(STATE_DIM, np.nan))
    with pytest.raises(ValueError, match="drift"):
        sh.filter_batch(np.stack([s, s]), [0, 0], np.zeros((2, 2)), np.zeros((1, STATE_DIM)))


def test_bounds_given_as_lists_equal_tuples() -> None:
    # Bounds read back from JSON (a run's run.json, a tune best.json) are lists.
    state = np.zeros(STATE_DIM)
    state[:2] = (0.3, -0.9)  # near the c1 wall, so the corrections are not zero
    state[3:] = (1.0, 2.0, 3.0, 1.0, 5.0, 5.2, 1.0, 3.0, 4.0, 2.0)  # goals, obstacles
    boxes = {"cbf_bounds": ((-1.5, -3.0), (1.5, 3.0)), "clf_bounds": ((-0.3, -0.6), (0.3, 0.6))}
    as_lists = {k: [list(side) for side in v] for k, v in boxes.items()}
    a = task_shield(**boxes).filter(state, 0, np.array([0.5, -1.0]))
    b = task_shield(**as_lists).filter(state, 0, np.array([0.5, -1.0]))
    assert np.any(a.a_cbf != 0)
    assert np.array_equal(a.a_cbf, b.a_cbf) and np.array_equal(a.a_clf, b.a_clf)
    with pytest.raises(TypeError, match="cbf_bounds: expected a pair"):
        task_shield(cbf_bounds=[-1.0, 0.0, 1.0])
    with pytest.raises(TypeError, match="cbf_bounds: expected a pair"):
        task_shield(cbf_bounds="ab")
