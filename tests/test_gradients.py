"""Gradients through the shield (issue 35): ``Shield.vjp_batch`` and ``tlshield.torch``.

Checked against three independent references: central finite differences of the shielded
action, a dense differentiable QP on the same problems (cvxpylayers: the rows in torch with
autograd's own derivatives, the QP through diffcp and Clarabel; ``tests/grad_reference.py``),
and ``torch.autograd.gradcheck``. Each check also asserts that enough of its rows were actually
corrected by the shield, so that an identity gradient cannot pass it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import tlshield
from tests.fixtures import PARAMS, task_shield
from tests.shield_reference import Structure
from tlshield import GradFlag, ShieldError, Status
from tlshield.envs.channel_task import ChannelParams, channel_shield

torch = pytest.importorskip("torch")


def _state(x: float, offset: float, theta: float, goals: np.ndarray) -> np.ndarray:
    """A case-study state: reference point at (x + offset/2, x - offset/2) (offset = x - y,
    |offset| < 1.5 inside the channel), heading theta, goal centres, obstacles far away."""
    s = np.zeros(13)
    s[0], s[1], s[2] = x + offset / 2, x - offset / 2, theta
    s[3:9] = goals
    s[9:13] = [20.0, 20.0, 20.0, -20.0]
    return s


def _instances(rng: np.random.Generator, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Random states and RL actions where the shield acts: three rows in four near a wall
    (the CBF), goals g1 and g2 just outside reach (0.55-1) in every other row, with small
    actions (where the CLF's box can meet its row, so that a_clf moves with the input)."""
    states, actions = [], []
    for i in range(count):
        near_wall = i % 4 != 3
        offset = rng.choice([-1, 1]) * rng.uniform(1.1, 1.45) if near_wall else rng.uniform(-1, 1)
        s = _state(rng.uniform(-1, 8), offset, rng.uniform(-3, 3), rng.uniform(-1.0, 10.0, 6))
        if i % 2:
            for k in (3, 5):
                angle, r = rng.uniform(-math.pi, math.pi), rng.uniform(0.55, 1.0)
                s[k : k + 2] = s[:2] + r * np.array([math.cos(angle), math.sin(angle)])
        states.append(s)
        scale = 0.1 if i % 2 else 1.0
        actions.append(scale * rng.uniform([-4, -6], [4, 6]))
    return np.array(states), np.array(actions)


def _shielded(shield: tlshield.Shield, s: np.ndarray, q: np.ndarray, a: np.ndarray) -> np.ndarray:
    return shield.filter_batch(s, q, a).action


def _finite_differences(
    shield: tlshield.Shield, s: np.ndarray, q: np.ndarray, a: np.ndarray, v: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Central differences of ``v . action`` in every a_rl and state value, row by row (the
    FSA states held fixed, as the gradient holds them)."""
    eps = 1e-6
    value = lambda s_, a_: (_shielded(shield, s_, q, a_) * v).sum(axis=1)  # noqa: E731
    ga = np.empty_like(a)
    for j in range(a.shape[1]):
        d = np.zeros_like(a)
        d[:, j] = eps
        ga[:, j] = (value(s, a + d) - value(s, a - d)) / (2 * eps)
    gs = np.empty_like(s)
    for i in range(s.shape[1]):
        d = np.zeros_like(s)
        d[:, i] = eps
        gs[:, i] = (value(s + d, a) - value(s - d, a)) / (2 * eps)
    return ga, gs


@pytest.mark.parametrize(
    "parts", [(True, True), (True, False), (False, True)], ids=["cbf_clf", "cbf", "clf"]
)
def test_vjp_matches_finite_differences(parts: tuple[bool, bool]) -> None:
    """dL/da_rl and dL/ds equal central differences (1e-5) on every row not flagged, and
    most rows are neither flagged nor left uncorrected."""
    shield = task_shield(use_cbf=parts[0], use_clf=parts[1])
    rng = np.random.default_rng(7)
    s, a = _instances(rng, 200)
    q = np.array([shield.automaton.step(x, 0) for x in s])
    v = rng.normal(size=a.shape)
    ga, gs, flags = shield.vjp_batch(s, q, a, v)
    fa, fs = _finite_differences(shield, s, q, a, v)
    ok = flags == 0
    corrected = (np.abs(ga - v).max(axis=1) > 1e-3) | (np.abs(gs).max(axis=1) > 1e-3)
    assert ok.sum() >= 150 and (ok & corrected).sum() >= 30, (ok.sum(), (ok & corrected).sum())
    np.testing.assert_allclose(ga[ok], fa[ok], atol=1e-5, rtol=1e-5)
    np.testing.assert_allclose(gs[ok], fs[ok], atol=1e-5, rtol=1e-5)


def test_vjp_matches_finite_differences_on_channel_v0() -> None:
    """The env's shield (obstacle barriers read from the state, RL bounds, drift of the moving
    obstacles) on states of real episodes, with obstacles placed next to the agent."""
    cfg = ChannelParams()
    shield = channel_shield(cfg, "rl_cbf_clf")
    assert shield is not None
    rng = np.random.default_rng(5)
    s, a = _instances(rng, 160)
    # Obstacles at 0.5-0.9 of the agent, in random directions.
    for row in s:
        for k in (9, 11):
            angle, r = rng.uniform(-math.pi, math.pi), rng.uniform(0.5, 0.9)
            row[k : k + 2] = row[:2] + r * np.array([math.cos(angle), math.sin(angle)])
    a = np.clip(a / 4, [-1, -2], [1, 2])
    drift = rng.normal(scale=0.3, size=s.shape) * (np.arange(13) >= 9)
    q = np.array([shield.automaton.step(x, shield.automaton.initial) for x in s])
    v = rng.normal(size=a.shape)
    ga, gs, flags = shield.vjp_batch(s, q, a, v, drift)
    eps = 1e-6

    def value(s_: np.ndarray, a_: np.ndarray) -> np.ndarray:
        return (shield.filter_batch(s_, q, a_, drift).action * v).sum(axis=1)

    ok = flags == 0
    corrected = (np.abs(ga - v).max(axis=1) > 1e-3) | (np.abs(gs).max(axis=1) > 1e-3)
    # Obstacles next to the agent: many random turns steer into one and are released to the
    # CLF's box (issue 59), flagged ROUTED, whose dL/da_rl is exact (checked below).
    routed = flags == tlshield.GradFlag.ROUTED
    assert ok.sum() >= 60 and (ok & corrected).sum() >= 20, (ok.sum(), (ok & corrected).sum())
    assert (ok | routed).sum() >= 120, (ok | routed).sum()
    for i in range(13):
        d = np.zeros_like(s)
        d[:, i] = eps
        fd = (value(s + d, a) - value(s - d, a)) / (2 * eps)
        np.testing.assert_allclose(gs[ok, i], fd[ok], atol=1e-5, rtol=1e-5, err_msg=f"s[{i}]")
    for j in range(2):
        d = np.zeros_like(a)
        d[:, j] = eps
        fd = (value(s, a + d) - value(s, a - d)) / (2 * eps)
        exact = ok | routed
        np.testing.assert_allclose(ga[exact, j], fd[exact], atol=1e-5, rtol=1e-5, err_msg=f"a[{j}]")


# cvxpylayers 1.0.4 warns about its own numpy 2 arrays on every solve.
@pytest.mark.filterwarnings("ignore:__array__ implementation:DeprecationWarning")
def test_vjp_equals_cvxpylayers_to_1e_6() -> None:
    """The same QPs through cvxpylayers (rows in torch, derivatives by autograd and diffcp):
    both gradients agree to 1e-6 on every covered, unflagged row that cvxpylayers itself solves
    accurately.

    diffcp's interior-point answer is only accurate to ~1e-5 on some of these problems (the CLF's
    linear cost K = 1e4 against actions of order 0.1; measured: 24 of 57 rows further than 1e-8
    from the exact action, the worst 3.5e-5). A gradient of an inexact solution cannot be
    compared at 1e-6, so rows where its forward action is more than 1e-7 from ours are left
    out (the core's actions are checked against cvxpy in test_shield.py and its gradients
    against finite differences above), and at least 40 rows must remain."""
    pytest.importorskip("cvxpylayers")
    from tests.grad_reference import ReferenceLayer

    shield = task_shield()
    reference = ReferenceLayer(PARAMS, Structure(shield.automaton))
    rng = np.random.default_rng(11)
    s, a = _instances(rng, 80)
    q = np.array([shield.automaton.step(x, 0) for x in s])
    v = rng.normal(size=a.shape)
    ga, gs, flags = shield.vjp_batch(s, q, a, v)
    actions = shield.filter_batch(s, q, a).action
    compared = corrected = inexact = 0
    for i in range(len(s)):
        if flags[i]:
            continue
        want = reference.gradients(s[i], int(q[i]), a[i], v[i])
        if want is None:  # the goal is the deepest point of several regions
            continue
        if np.abs(want[2] - actions[i]).max() > 1e-7:
            inexact += 1
            continue
        compared += 1
        corrected += int(np.abs(ga[i] - v[i]).max() > 1e-3 or np.abs(gs[i]).max() > 1e-3)
        np.testing.assert_allclose(ga[i], want[0], atol=1e-6, rtol=0, err_msg=f"row {i}")
        np.testing.assert_allclose(gs[i], want[1], atol=1e-6, rtol=0, err_msg=f"row {i}")
    assert compared >= 40 and corrected >= 15, (compared, corrected, inexact)


def _layer_rows(shield: tlshield.Shield, count: int, seed: int) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    s, a = _instances(rng, count)
    q = np.array([shield.automaton.step(x, 0) for x in s])
    return s, q, a


def test_gradcheck_through_the_layer() -> None:
    """torch.autograd.gradcheck in float64, with respect to a_rl and the states, on random
    states whose rows are not degenerate."""
    from tlshield.torch import ShieldLayer

    shield = task_shield()
    s, q, a = _layer_rows(shield, 64, 3)
    flags = shield.vjp_batch(s, q, a, np.ones_like(a))[2]
    keep = flags == 0
    s, q, a = s[keep][:24], q[keep][:24], a[keep][:24]
    corrected = np.abs(shield.filter_batch(s, q, a).action - a).max(axis=1) > 1e-3
    assert corrected.sum() >= 6
    layer = ShieldLayer(shield)
    s_t = torch.tensor(s, requires_grad=True)
    a_t = torch.tensor(a, requires_grad=True)
    assert torch.autograd.gradcheck(
        lambda a_, s_: layer(s_, q, a_), (a_t, s_t), eps=1e-6, atol=1e-5, rtol=1e-4
    )
    assert layer.last_flags is not None and not layer.last_flags.any()


def test_layer_dtypes_and_what_it_returns() -> None:
    """float32 in, float32 out (and float32 gradients); the forward pass equals filter_batch;
    no state gradient is computed when the states do not ask for one."""
    from tlshield.torch import ShieldLayer

    shield = task_shield()
    s, q, a = _layer_rows(shield, 16, 4)
    layer = ShieldLayer(shield)
    a32 = torch.tensor(a, dtype=torch.float32, requires_grad=True)
    out = layer(torch.tensor(s, dtype=torch.float32), q, a32)
    assert out.dtype == torch.float32 and out.shape == (16, 2)
    want = shield.filter_batch(s.astype(np.float32).astype(float), q, a.astype(np.float32))
    np.testing.assert_allclose(out.detach().numpy(), want.action, rtol=1e-6, atol=1e-6)
    out.sum().backward()
    assert a32.grad is not None and a32.grad.dtype == torch.float32
    assert layer.last_flags is not None and layer.last_flags.shape == (16,)
    with torch.no_grad():  # no gradient wanted: the plain batch call
        np.testing.assert_array_equal(
            layer(torch.tensor(s), q, torch.tensor(a)).numpy(), shield.filter_batch(s, q, a).action
        )
    with pytest.raises(TypeError, match="a_rl"):
        layer(torch.tensor(s), q)
    with pytest.raises(TypeError, match="shield"):
        ShieldLayer("not a shield")  # type: ignore[arg-type]


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_layer_packed_transfer_equals_the_direct_path(dtype: str) -> None:
    """The GPU path's packing (every input to the host in one block, the actions and both
    gradients back in one), run on the CPU: the same actions and gradients as the direct path,
    bit for bit, FSA states given as a tensor, states asking for gradients."""
    from tlshield.torch import ShieldLayer

    shield = task_shield()
    s, q, a = _layer_rows(shield, 12, 6)
    tdtype = getattr(torch, dtype)
    weights = torch.linspace(-1, 1, 24, dtype=tdtype).reshape(12, 2)
    results = []
    for pack in (False, True):
        layer = ShieldLayer(shield)
        layer._pack = pack
        a_t = torch.tensor(a, dtype=tdtype, requires_grad=True)
        s_t = torch.tensor(s, dtype=tdtype, requires_grad=True)
        out = layer(s_t, torch.tensor(q), a_t)
        (out * weights).sum().backward()
        assert out.dtype == tdtype and a_t.grad is not None and s_t.grad is not None
        results.append((out.detach(), a_t.grad, s_t.grad))
    for direct, packed in zip(*results, strict=True):
        torch.testing.assert_close(packed, direct, rtol=0, atol=0)
    assert results[0][2].abs().sum() > 0  # the states' gradient is not trivially zero
    layer = ShieldLayer(shield)
    layer._pack = True
    with pytest.raises(TypeError, match="qs"):
        layer(torch.tensor(s), torch.tensor(q, dtype=torch.float64), torch.tensor(a))


def test_layer_on_monitors_differentiates_the_step_taken() -> None:
    """layer(monitors, a_rl) equals layer(states, qs, a_rl), and its backward pass after the
    monitors have advanced still differentiates the rows of the forward pass."""
    from tlshield.torch import ShieldLayer

    shield = task_shield()
    s, _, a = _layer_rows(shield, 8, 5)
    monitors = tlshield.MonitorBatch(shield.automaton, len(s))
    monitors.reset(s)
    layer = ShieldLayer(shield)
    a1 = torch.tensor(a, requires_grad=True)
    out = layer(monitors, a1)
    a2 = torch.tensor(a, requires_grad=True)
    want = layer(torch.tensor(monitors.states), monitors.q, a2)
    torch.testing.assert_close(out, want)
    monitors.advance(s + 0.3)  # the episode moves on before the backward pass
    weights = torch.linspace(-1, 1, 16, dtype=torch.float64).reshape(8, 2)
    (out * weights).sum().backward()
    (want * weights).sum().backward()
    torch.testing.assert_close(a1.grad, a2.grad)


def test_relaxed_and_failed_steps_are_flagged() -> None:
    """Outside the channel the QP is relaxed: flagged RELAXED, and the gradient is the relaxed
    problem's (finite differences agree). A step that fails returns a_rl: flagged FAILED with
    the identity gradient."""
    shield = task_shield()
    s = _state(2.0, 3.0, math.pi / 4, np.array([4.0, 4.0, 4.5, 6.5, 9.0, 9.0]))[None]
    q = np.array([shield.automaton.step(s[0], 0)])
    a = np.array([[2.0, -1.0]])
    v = np.array([[0.7, -0.4]])
    assert shield.filter_batch(s, q, a).status[0] == Status.RELAXED
    ga, gs, flags = shield.vjp_batch(s, q, a, v)
    assert flags[0] & GradFlag.RELAXED and not flags[0] & GradFlag.FAILED
    fa, fs = _finite_differences(shield, s, q, a, v)
    np.testing.assert_allclose(ga, fa, atol=1e-5)
    np.testing.assert_allclose(gs, fs, atol=1e-5)

    # 14 barriers outside their sets: the relaxed QP has 19 variables, more than the
    # active-set solver holds, and only that solver is allowed.
    barriers = {
        f"b{i}": tlshield.Inside(
            tlshield.Halfspace(np.r_[1.0, -1.0, np.zeros(11)], -2.0 - 0.01 * i)
        )
        for i in range(14)
    }
    failing = task_shield(barriers=barriers, solver="active_set")
    assert failing.filter_batch(s, q, a).status[0] == Status.FAILED
    ga, gs, flags = failing.vjp_batch(s, q, a, v)
    assert flags[0] == GradFlag.FAILED
    np.testing.assert_array_equal(ga, v)
    np.testing.assert_array_equal(gs, np.zeros_like(s))


def test_degenerate_point_is_flagged_and_one_sided() -> None:
    """With a_rl exactly on the boundary where the wall's row becomes active (tight, zero
    multiplier), the row is flagged DEGENERATE and the gradient is the derivative of the piece
    on which the row stays tight: the one-sided difference into the corrected side."""
    shield = task_shield(use_clf=False)
    s = _state(1.0, -1.2, math.pi / 2, np.array([4.0, 4.0, 4.5, 6.5, 9.0, 9.0]))
    q = shield.automaton.step(s, 0)
    # c1: h = x - y + 1.5, Lg h = [cos - sin, -0.1 (sin + cos)]; at theta = pi/2, [-1, -0.1].
    h = s[0] - s[1] + 1.5
    lg = np.array([-1.0, -0.1])
    # Lg h . a + alpha (h - margin) = 0 with a = t * lg / |lg|^2 * (-1).
    a = -PARAMS.alpha * (h - PARAMS.margin) * lg / (lg @ lg)
    assert np.allclose(shield.filter(s, q, a).a_cbf, 0.0, atol=1e-9)
    v = np.array([[1.0, 0.5]])
    ga, _, flags = shield.vjp_batch(s[None], [q], a[None], v)
    assert flags[0] & GradFlag.DEGENERATE
    # Into the corrected side: a moves further along lg's negative direction.
    eps = 1e-6
    push = -lg / np.linalg.norm(lg) * eps
    one_sided = []
    for j in range(2):
        d = np.zeros(2)
        d[j] = eps
        inside = (_shielded(shield, s[None], [q], (a + push + d)[None]) * v).sum()
        outside = (_shielded(shield, s[None], [q], (a + push - d)[None]) * v).sum()
        one_sided.append((inside - outside) / (2 * eps))
    np.testing.assert_allclose(ga[0], one_sided, atol=1e-5)


def test_state_gradients_are_refused_where_they_are_not_available() -> None:
    """HOCBF rows and a user's per-call model: a clear ShieldError for state gradients,
    action gradients still available; bad input names its argument."""
    model = tlshield.AccelerationUnicycle(x=0, y=1, theta=2, v=12)
    shield = task_shield(model=model, alpha2=2.0)
    s, q, a = _layer_rows(shield, 4, 6)
    s[:, 12] = 0.5
    with pytest.raises(ShieldError, match="second-order"):
        shield.vjp_batch(s, q, a, np.ones_like(a))
    ga, gs, flags = shield.vjp_batch(s, q, a, np.ones_like(a), state_grad=False)
    assert ga.shape == (4, 2) and gs is None and flags.shape == (4,)

    plain = task_shield()
    with pytest.raises(ValueError, match="grad_action"):
        plain.vjp_batch(s, q, a, np.full_like(a, np.nan))
    with pytest.raises(ValueError, match="grad_action"):
        plain.vjp_batch(s, q, a, np.ones((4, 3)))
    with pytest.raises(ValueError, match="qs"):
        plain.vjp_batch(s, q[:2], a, np.ones_like(a))


def test_jacobian_batch_is_the_vjps_of_unit_vectors() -> None:
    """jacobian_batch's rows are vjp_batch with the unit vectors, and its actions are
    filter_batch's, on the env's shield with drift."""
    shield = task_shield()
    s, q, a = _layer_rows(shield, 48, 8)
    drift = np.random.default_rng(8).normal(scale=0.2, size=s.shape) * (np.arange(13) >= 9)
    action, jac_a, jac_s, flags = shield.jacobian_batch(s, q, a, drift)
    np.testing.assert_array_equal(action, shield.filter_batch(s, q, a, drift).action)
    assert jac_a.shape == (48, 2, 2) and jac_s is not None and jac_s.shape == (48, 2, 13)
    for k in range(2):
        unit = np.zeros_like(a)
        unit[:, k] = 1.0
        ga, gs, f = shield.vjp_batch(s, q, a, unit, drift)
        np.testing.assert_array_equal(jac_a[:, k], ga)
        np.testing.assert_array_equal(jac_s[:, k], gs)
        np.testing.assert_array_equal(f, flags)
    assert shield.jacobian_batch(s, q, a, state_grad=False)[2] is None


def test_import_tlshield_still_loads_no_torch() -> None:
    import subprocess
    import sys

    code = "import sys, tlshield; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
