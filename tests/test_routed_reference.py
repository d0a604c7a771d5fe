"""The routed shield (the default) against an independent solve and finite differences (issue
57, item 6). Routing only changes the CLF row's target and credit; the QP the shield then
solves (``Shield.problem``) is solved again by cvxpy with CLARABEL, and the action must agree.
Its ``dL/da_rl`` on rows flagged ``GradFlag.ROUTED`` is exact (the route is fixed in ``a_rl``):
it must equal central differences of the action."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

import tlshield
from tlshield import GradFlag, Status
from tlshield.lab import routing

cp = pytest.importorskip("cvxpy")


def scene(robot: str, seed: int) -> tuple[tlshield.Shield, np.ndarray, np.ndarray, np.ndarray]:
    """The routing lab's shield for ``robot`` among eight random discs (obstacles as
    barriers, routing on), and 200 states around them with random RL actions."""
    rng = np.random.default_rng(seed)
    goal = routing.GOAL
    obstacles = routing.layout("random8", rng)
    sh = routing.shield_for(robot, obstacles, goal, "barriers", route=True)
    model = routing.robot(robot)
    states, a_rl = [], []
    while len(states) < 200:
        p = rng.uniform([-2.2, -1.5], [1.8, 1.5])
        if any(np.linalg.norm(p - c) < r + 0.02 for c, r in obstacles):
            continue
        s = model.start(p)
        if robot == "unicycle":
            s[2] = rng.uniform(-np.pi, np.pi)
        if robot == "double":
            s[2:] = rng.uniform(-0.5, 0.5, 2)
        states.append(s)
        a_rl.append(0.5 * rng.uniform(-1.0, 1.0, 2))
    s_arr = np.array(states)
    q = np.full(len(s_arr), sh.automaton.initial)
    return sh, s_arr, q, np.array(a_rl)


def independent(problem: dict) -> np.ndarray | None:
    """cvxpy's solve of ``min x'Px/2 + c'x  s.t.  G x <= h`` (None when not optimal)."""
    n = len(problem["c"])
    x = cp.Variable(n)
    objective = 0.5 * cp.sum(cp.multiply(problem["P_diag"], cp.square(x))) + problem["c"] @ x
    prob = cp.Problem(cp.Minimize(objective), [problem["G"] @ x <= problem["h"]])
    prob.solve(solver="CLARABEL", tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10)
    return None if prob.status != "optimal" else np.asarray(x.value)


@pytest.mark.parametrize("robot", ["single", "unicycle", "double"])
def test_the_routed_shield_equals_an_independent_solve_and_its_gradient_is_exact(
    robot: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    # At the CLF box of the full limits, where these states were drawn: at the lab's half box
    # cvxpy reports one of the unicycle's QPs inaccurate (the shield solves it).
    monkeypatch.setattr(routing, "CLF_SHARE", 1.0)
    sh, states, q, a_rl = scene(robot, 3)
    m = sh.num_inputs
    batch = sh.filter_batch(states, q, a_rl)
    rng = np.random.default_rng(0)
    v = rng.normal(size=a_rl.shape)
    ga, _, flags = sh.vjp_batch(states, q, a_rl, v, state_grad=False)
    compared = routed = 0
    for i, (s, a) in enumerate(zip(states, a_rl, strict=True)):
        if batch.status[i] != Status.SOLVED:
            continue
        problem = sh.problem(s, q[i], a)
        if len(problem["c"]) != 2 * m + 1:  # no goal this step (it is reached)
            continue
        x = independent(problem)
        assert x is not None, f"row {i}: cvxpy found no optimum of a QP the shield solved"
        want = a + x[:m] + x[m : 2 * m]
        np.testing.assert_allclose(batch.action[i], want, atol=1e-5, rtol=0, err_msg=f"row {i}")
        compared += 1
        routed += bool(flags[i] & GradFlag.ROUTED)
    assert compared >= 100 and routed >= 20, (compared, routed)
    # dL/da_rl on the routed rows (and on no other flag) against central differences.
    only_routed = flags == GradFlag.ROUTED
    assert only_routed.sum() >= 20, only_routed.sum()
    assert_vjp_matches_differences(sh, states, q, a_rl, v, ga, only_routed)


def test_the_problem_is_checked_like_a_filter_call() -> None:
    sh, states, q, a_rl = scene("single", 1)
    with pytest.raises(tlshield.ShieldError, match="a_rl"):
        sh.problem(states[0], q[0], [np.nan, 0.0])
    with pytest.raises(tlshield.ShieldError):
        sh.problem(states[0][:1], q[0], a_rl[0])


def clf_box_rows(problem: dict, m: int, bounds: tuple) -> np.ndarray:
    """Per input, whether this step's CLF box (the rows on ``a_clf`` alone) differs from
    ``bounds``: the RL action's turn was released to it."""
    g, h = np.asarray(problem["G"]), np.asarray(problem["h"])
    lo, hi = (np.broadcast_to(np.asarray(b, dtype=float), (m,)) for b in bounds)
    widened = np.zeros(m, dtype=bool)
    for row, rhs in zip(g, h, strict=True):
        cols = np.flatnonzero(row)
        if len(cols) != 1 or not m <= cols[0] < 2 * m:
            continue
        j = cols[0] - m
        limit = hi[j] if row[cols[0]] > 0 else -lo[j]
        widened[j] |= not np.isclose(rhs, limit, rtol=0, atol=1e-12)
    return widened


@pytest.mark.parametrize("robot", ["unicycle", "accel_unicycle", "thrust_turn"])
def test_a_released_turn_widens_only_the_clf_box_and_its_gradient_is_exact(robot: str) -> None:
    """Issue 59, item 2: a greedy seeker's turn into a disc that blocks it is released to the
    CLF's box. The box widens only on the turn input (the barrier rows are the unrouted
    ones'), the step is flagged ``GradFlag.ROUTED``, and ``dL/da_rl`` through the widened box
    equals central differences of the action."""
    rng = np.random.default_rng(5)
    goal = routing.GOAL
    obstacles = routing.layout("random8", rng)
    sh = routing.shield_for(robot, obstacles, goal, "barriers", route=True)
    model = routing.robot(robot)
    bounds = model.shield_kwargs["clf_bounds"]
    states, a_rl = [], []
    while len(states) < 300:
        p = rng.uniform([-1.5, -1.5], [1.5, 1.5])
        gaps = [np.linalg.norm(p - c) - r for c, r in obstacles]
        if min(gaps) < 0.01 or min(gaps) > 0.3:  # outside every disc, near one
            continue
        s = model.start(p)
        s[2] = rng.uniform(-np.pi, np.pi)
        if robot != "unicycle":
            s[3] = rng.uniform(0.0, 0.3)
        states.append(s)
        a_rl.append(model.seeker(s, goal))
    s_arr, a_arr = np.array(states), np.array(a_rl)
    m = sh.num_inputs

    def released(problem: dict, a: np.ndarray) -> bool:
        if len(problem["c"]) != 2 * m + 1:
            return False
        widened = clf_box_rows(problem, m, bounds)
        # Only the turn input (the second) is released; the forward push never is.
        assert not widened[0], "the forward input's CLF box widened"
        return bool(widened[1])

    assert_released_rows_exact(sh, s_arr, a_arr, released, all_solved=False)


def assert_released_rows_exact(
    sh: tlshield.Shield,
    s_arr: np.ndarray,
    a_arr: np.ndarray,
    released: Callable[[dict, np.ndarray], bool],
    all_solved: bool,
) -> None:
    """On the rows whose QP ``released(problem, a_rl)`` says widened a CLF box by the RL
    action (at least 20 of them): the step is flagged ``GradFlag.ROUTED``, the action equals an
    independent solve of the same problem, and ``dL/da_rl`` equals central differences.
    ``all_solved``: every row's QP must be solved (else unsolved rows are passed over)."""
    m = sh.num_inputs
    q = np.full(len(s_arr), sh.automaton.initial)
    batch = sh.filter_batch(s_arr, q, a_arr)
    v = np.random.default_rng(0).normal(size=a_arr.shape)
    ga, _, flags = sh.vjp_batch(s_arr, q, a_arr, v, state_grad=False)
    rows = np.zeros(len(s_arr), dtype=bool)
    for i, (s, a) in enumerate(zip(s_arr, a_arr, strict=True)):
        if batch.status[i] != Status.SOLVED:
            assert not all_solved, f"row {i}: {batch.status[i]}"
            continue
        problem = sh.problem(s, q[i], a)
        rows[i] = released(problem, a)
        if rows[i]:
            assert flags[i] & GradFlag.ROUTED, f"row {i}: a released input is not flagged"
            x = independent(problem)
            assert x is not None
            want = a + x[:m] + x[m : 2 * m]
            np.testing.assert_allclose(batch.action[i], want, atol=1e-5, rtol=0)
    check = rows & (flags == GradFlag.ROUTED)
    assert check.sum() >= 20, check.sum()
    assert_vjp_matches_differences(sh, s_arr, q, a_arr, v, ga, check)


def assert_vjp_matches_differences(
    sh: tlshield.Shield,
    states: np.ndarray,
    q: np.ndarray,
    a_rl: np.ndarray,
    v: np.ndarray,
    ga: np.ndarray,
    rows: np.ndarray,
) -> None:
    """``v . dL/da_rl`` (``ga``) on ``rows`` against central differences of the batch action."""
    eps = 1e-6
    for j in range(a_rl.shape[1]):
        d = np.zeros_like(a_rl)
        d[:, j] = eps
        plus = (sh.filter_batch(states, q, a_rl + d).action * v).sum(axis=1)
        minus = (sh.filter_batch(states, q, a_rl - d).action * v).sum(axis=1)
        fd = (plus - minus) / (2 * eps)
        np.testing.assert_allclose(ga[rows, j], fd[rows], atol=1e-5, rtol=1e-5)
