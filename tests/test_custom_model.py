"""A user's own robot: ``ControlAffine`` models written as Python callables shield exactly as
the built-in models they copy (to 1e-9), keep barriers under attack, and a model or a call
that cannot act on a barrier is an error, never a silent pass. The kinematic bicycle steps as
its equations say and keeps its barriers under attack."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import tlshield

OBSTACLE, RADIUS = np.array([2.0, 0.1]), 0.5
GOAL = np.array([4.0, 0.0])
GAINS = {"alpha": 1.5, "alpha2": 2.0, "c3": 1.0, "k": 1e4, "clf_gain": 0.8}


def di_f(s: np.ndarray) -> np.ndarray:
    """The double integrator's drift over ``[x, y, vx, vy]``."""
    return np.array([s[2], s[3], 0.0, 0.0])


def di_g(s: np.ndarray) -> np.ndarray:
    return np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])


def di_jacobian(s: np.ndarray) -> np.ndarray:
    j = np.zeros((4, 4))
    j[0, 2] = j[1, 3] = 1.0
    return j


def au_f(s: np.ndarray) -> np.ndarray:
    """The acceleration unicycle's drift over ``[x, y, theta, v]``."""
    return np.array([s[3] * np.cos(s[2]), s[3] * np.sin(s[2]), 0.0, 0.0])


def au_g(s: np.ndarray) -> np.ndarray:
    return np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 1.0], [1.0, 0.0]])


EPS = 0.1


def uni_f(s: np.ndarray) -> np.ndarray:
    return np.zeros(3)


def uni_g(s: np.ndarray) -> np.ndarray:
    """The paper's unicycle reference point (Eq. 6A2) over ``[x, y, theta]``."""
    c, si = np.cos(s[2]), np.sin(s[2])
    return np.array([[c, -EPS * si], [si, EPS * c], [0.0, 1.0]])


def shield(model: object, **overrides: object) -> tlshield.Shield:
    spec = tlshield.Spec("F g", {"g": tlshield.Ball(pos=[0, 1], radius=0.3, center=GOAL)})
    kwargs: dict[str, object] = {
        **GAINS,
        "cbf_bounds": (-6.0, 6.0),
        "clf_bounds": (-0.5, 0.5),
        "barriers": {
            "!o": tlshield.Avoid(tlshield.Ball(pos=[0, 1], radius=RADIUS, center=OBSTACLE))
        },
        **overrides,
    }
    return tlshield.Shield(spec, model, **kwargs)  # type: ignore[arg-type]


def states(rng: np.random.Generator, count: int, n: int) -> np.ndarray:
    """States with positions away from the obstacle's centre and the goal."""
    out = []
    while len(out) < count:
        s = rng.uniform(-3.0, 3.0, n)
        s[:2] = rng.uniform([-2.0, -3.0], [6.0, 3.0])
        if np.linalg.norm(s[:2] - OBSTACLE) > 0.05 and np.linalg.norm(s[:2] - GOAL) > 0.35:
            out.append(s)
    return np.array(out)


@pytest.mark.parametrize("exact_jacobian", [True, False], ids=["jacobian", "differences"])
@pytest.mark.parametrize(
    ("built_in", "f", "g", "jacobian"),
    [
        (tlshield.DoubleIntegrator(pos=[0, 1], vel=[2, 3]), di_f, di_g, di_jacobian),
        (tlshield.AccelerationUnicycle(), au_f, au_g, None),
        (tlshield.Unicycle(EPS), uni_f, uni_g, None),
    ],
    ids=["double-integrator", "acceleration-unicycle", "unicycle"],
)
def test_a_custom_model_gives_the_built_in_models_actions(
    built_in: object, f: object, g: object, jacobian: object, exact_jacobian: bool
) -> None:
    n = 3 if isinstance(built_in, tlshield.Unicycle) else 4
    given = jacobian if exact_jacobian else None
    custom = tlshield.ControlAffine(f, g, state_dim=n, inputs=2, jacobian=given)  # type: ignore[arg-type]
    extra = {} if n == 4 else {"alpha2": None}
    # A custom model declares the heading its turn input steers (the built-in unicycles know
    # their own), so that routing's CLF turns it alike and releases a turn into an obstacle
    # alike.
    turns = (tlshield.AccelerationUnicycle, tlshield.Unicycle)
    declared = {"heading": 2} if isinstance(built_in, turns) else {}
    a, b = shield(built_in, **extra), shield(custom, **extra, **declared)
    rng = np.random.default_rng(0)
    xs = states(rng, 300, n)
    a_rl = rng.uniform(-4.0, 4.0, (300, 2))
    for s, u in zip(xs, a_rl, strict=True):
        want, got = a.filter(s, 0, u), b.filter(s, 0, u)
        np.testing.assert_allclose(got.action, want.action, rtol=0, atol=1e-9)
        assert got.status == want.status
    batch_a, batch_b = (
        a.filter_batch(xs, np.zeros(300, int), a_rl),
        b.filter_batch(xs, np.zeros(300, int), a_rl),
    )
    np.testing.assert_allclose(batch_b.action, batch_a.action, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(batch_b.status, batch_a.status)
    # The monitor paths too.
    monitors = tlshield.MonitorBatch(b.automaton, 300)
    monitors.reset(xs)
    by_monitor = b.filter_monitors(monitors, a_rl)
    np.testing.assert_allclose(by_monitor.action, batch_a.action, rtol=0, atol=1e-9)
    one = tlshield.Monitor(b.automaton)
    one.reset(xs[0])
    np.testing.assert_allclose(b.filter_monitor(one, a_rl[0]).action, batch_a.action[0], atol=1e-9)


@pytest.mark.parametrize("model_name", ["custom", "built-in"])
def test_a_custom_double_integrator_keeps_the_obstacle_under_attack(model_name: str) -> None:
    """An attacker drives straight at the obstacle at full thrust; the shielded robot, stepped
    by the model's own Euler step, never enters it."""
    custom = tlshield.ControlAffine(di_f, di_g, state_dim=4, inputs=2)
    model = custom if model_name == "custom" else tlshield.DoubleIntegrator([0, 1], [2, 3])
    sh = shield(model, use_clf=False)
    violations = 0
    rng = np.random.default_rng(1)
    for _ in range(10):
        s = np.array([rng.uniform(-1.5, 0.0), rng.uniform(-1.0, 1.0), 0.0, 0.0])
        for _ in range(300):
            push = OBSTACLE - s[:2]
            a_rl = 3.0 * push / np.linalg.norm(push)
            s = model.step(s, sh.filter(s, 0, a_rl).action, 0.01)  # type: ignore[union-attr]
            violations += int(np.linalg.norm(s[:2] - OBSTACLE) <= RADIUS)
    assert violations == 0
    # The same attack unshielded does enter it: the test can fail.
    s = np.array([-1.0, 0.1, 0.0, 0.0])
    inside = 0
    for _ in range(300):
        push = OBSTACLE - s[:2]
        s = custom.step(s, 3.0 * push / np.linalg.norm(push), 0.01)
        inside += int(np.linalg.norm(s[:2] - OBSTACLE) <= RADIUS)
    assert inside > 0


def test_without_a_model_a_call_that_cannot_act_is_an_error_not_a_silent_pass() -> None:
    """The issue's 15 lines: a double integrator given only as per-call f, g, a wall x <= 1 and
    an RL action pushing +1. Before, x reached 49.75 with no error."""
    spec = tlshield.Spec("F g", {"g": tlshield.Halfspace([1.0, 0.0], -5.0)})
    wall = {"wall": tlshield.Inside(tlshield.Halfspace([-1.0, 0.0], 1.0))}
    kw = {"alpha": 2.0, "c3": 1.0, "k": 1e4, "barriers": wall, "pos": [0], "use_clf": False}
    sh = tlshield.Shield(spec, None, cbf_bounds=(-4.0, 4.0), clf_bounds=(-1.0, 1.0), inputs=1, **kw)  # type: ignore[arg-type]
    s = np.zeros(2)
    with pytest.raises(tlshield.ShieldError, match=r'barrier "wall".*Lg h = 0.*ControlAffine'):
        sh.filter(s, 0, [1.0], f=[s[1], 0.0], g=[[0.0], [1.0]])
    # A velocity-level g acts on the wall: the first-order row holds it.
    for _ in range(200):
        s[0] += 0.05 * sh.filter(s, 0, [1.0], f=[0.0, 0.0], g=[[1.0], [0.0]]).action[0]
    assert s[0] < 1.0
    # Scalar bounds do not say how many inputs a model-less shield has.
    with pytest.raises(ValueError, match="inputs=m, or per-input bounds"):
        tlshield.Shield(spec, None, cbf_bounds=(-4.0, 4.0), clf_bounds=(-1.0, 1.0), **kw)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="inputs = 3, but the model has 2 inputs"):
        shield(tlshield.DoubleIntegrator([0, 1], [2, 3]), inputs=3)
    per_input = tlshield.Shield(
        spec, None, cbf_bounds=([-4.0], [4.0]), clf_bounds=([-1.0], [1.0]), **kw
    )  # type: ignore[arg-type]
    assert per_input.num_inputs == 1


def test_a_custom_model_that_cannot_act_on_a_barrier_is_refused_at_construction() -> None:
    # Inputs move only vx; a barrier on y is beyond two integrations of any input.
    model = tlshield.ControlAffine(
        di_f, lambda s: np.array([[0.0], [0.0], [1.0], [0.0]]), state_dim=4, inputs=1
    )
    assert model.actuated == [2] and model.integrated == [0]
    spec = tlshield.Spec("F g", {"g": tlshield.Halfspace([1.0, 0.0, 0.0, 0.0], -5.0)})
    bounds = {"cbf_bounds": (-1.0, 1.0), "clf_bounds": (-1.0, 1.0)}
    floor = {"floor": tlshield.Inside(tlshield.Halfspace([0.0, 1.0, 0.0, 0.0], 1.0))}
    with pytest.raises(tlshield.ShieldError, match=r'barrier "floor".*cannot\s+enforce'):
        tlshield.Shield(spec, model, **GAINS, **bounds, barriers=floor, pos=[0])  # type: ignore[arg-type]
    # A barrier on x has relative degree 2: without alpha2 the shield says so.
    wall = {"wall": tlshield.Inside(tlshield.Halfspace([-1.0, 0.0, 0.0, 0.0], 1.0))}
    gains = {**GAINS, "alpha2": None}
    with pytest.raises(tlshield.ShieldError, match=r"relative degree 2.*alpha2"):
        tlshield.Shield(spec, model, **gains, **bounds, barriers=wall, pos=[0])  # type: ignore[arg-type]
    # And the model gives f and g itself.
    sh = tlshield.Shield(spec, model, **GAINS, **bounds, barriers=wall, pos=[0])  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="do not pass them"):
        sh.filter(np.zeros(4), 0, [0.0], f=np.zeros(4), g=np.zeros((4, 1)))


def test_bad_callables_are_clear_errors_at_construction() -> None:
    with pytest.raises(TypeError, match="ControlAffine f: expected a callable s -> array or a"):
        tlshield.ControlAffine("f", di_g, state_dim=4, inputs=2)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"ControlAffine g: expected shape \(4, 2\), got \(4, 1\)"):
        tlshield.ControlAffine(di_f, np.ones((4, 1)), state_dim=4, inputs=2)
    with pytest.raises(ValueError, match=r"g\(s\): expected shape \(4, 2\), got \(4, 1\)"):
        tlshield.ControlAffine(di_f, lambda s: np.ones((4, 1)), state_dim=4, inputs=2)
    with pytest.raises(ValueError, match=r"f.*probe state"):
        tlshield.ControlAffine(lambda s: np.full(4, np.nan), di_g, state_dim=4, inputs=2)
    with pytest.raises(ValueError, match="g is zero everywhere"):
        tlshield.ControlAffine(di_f, lambda s: np.zeros((4, 2)), state_dim=4, inputs=2)
    at_least_one = "state_dim, inputs: expected at least one state value and one input"
    with pytest.raises(ValueError, match=f"{at_least_one}, got state_dim=0, inputs=2"):
        tlshield.ControlAffine(di_f, di_g, state_dim=0, inputs=2)
    with pytest.raises(ValueError, match=f"{at_least_one}, got state_dim=4, inputs=0"):
        tlshield.ControlAffine(di_f, di_g, state_dim=4, inputs=0)
    with pytest.raises(RuntimeError, match="boom"):

        def fails(s: np.ndarray) -> np.ndarray:
            raise RuntimeError("boom")

        tlshield.ControlAffine(fails, di_g, state_dim=4, inputs=2)
    # A model defined only where x > 0 is probed where the user says.
    sqrt_f = lambda s: np.array([np.sqrt(s[0]), 0.0])  # noqa: E731
    one = lambda s: np.array([[0.0], [1.0]])  # noqa: E731
    with pytest.raises(ValueError, match="probe state"), np.errstate(invalid="ignore"):
        tlshield.ControlAffine(sqrt_f, one, state_dim=2, inputs=1)
    probed = tlshield.ControlAffine(sqrt_f, one, state_dim=2, inputs=1, probe=[[1.0, 0.0]])
    assert probed.actuated == [1] and probed.integrated == []


def test_parts_that_do_not_depend_on_the_state_may_be_arrays() -> None:
    """A constant g and the Jacobian of a linear f, given as arrays, are the callables'
    model; the arrays are copied (changing the caller's array later changes nothing)."""
    g, jac = di_g(np.zeros(4)), di_jacobian(np.zeros(4))
    by_arrays = tlshield.ControlAffine(di_f, g, state_dim=4, inputs=2, jacobian=jac)
    by_calls = tlshield.ControlAffine(di_f, di_g, state_dim=4, inputs=2, jacobian=di_jacobian)
    g[:] = 0.0
    a, b = shield(by_arrays), shield(by_calls)
    rng = np.random.default_rng(5)
    for s in states(rng, 50, 4):
        u = rng.uniform(-4.0, 4.0, 2)
        np.testing.assert_array_equal(a.filter(s, 0, u).action, b.filter(s, 0, u).action)
    back = pickle.loads(pickle.dumps(by_arrays))
    np.testing.assert_array_equal(back.eval(np.ones(4))[1], di_g(np.ones(4)))


def test_a_custom_model_pickles_with_its_named_functions() -> None:
    model = tlshield.ControlAffine(di_f, di_g, state_dim=4, inputs=2, jacobian=di_jacobian)
    sh = shield(model)
    back = pickle.loads(pickle.dumps(sh))
    s, a = np.array([0.5, 0.2, 1.0, -0.3]), np.array([2.0, 0.0])
    np.testing.assert_array_equal(back.filter(s, 0, a).action, sh.filter(s, 0, a).action)
    assert repr(pickle.loads(pickle.dumps(model))) == repr(model)
    np.testing.assert_allclose(model.drift_jacobian(s), di_jacobian(s))


def test_the_kinematic_bicycle_steps_as_its_equations() -> None:
    bike = tlshield.KinematicBicycle(0.5)
    s = np.array([1.0, 2.0, np.pi / 3, 2.0])
    a = np.array([0.5, 0.2])  # acceleration, tan(steering)
    dt = 0.1
    want = s + dt * np.array([s[3] * np.cos(s[2]), s[3] * np.sin(s[2]), s[3] * a[1] / 0.5, a[0]])
    np.testing.assert_allclose(bike.step(s, a, dt), want, rtol=0, atol=1e-15)
    assert repr(bike) == "KinematicBicycle(wheelbase=0.5, x=0, y=1, theta=2, v=3)"
    assert pickle.loads(pickle.dumps(bike)).wheelbase == 0.5
    with pytest.raises(ValueError, match="wheelbase"):
        tlshield.KinematicBicycle(0.0)
    # The same model as a ControlAffine gives the same shield.
    custom = tlshield.ControlAffine(
        au_f,
        lambda s: np.array([[0.0, 0.0], [0.0, 0.0], [0.0, s[3] / 0.5], [1.0, 0.0]]),
        state_dim=4,
        inputs=2,
    )
    # A custom car declares its heading and its speed, as the built-in model knows its own.
    a_sh, b_sh = shield(bike), shield(custom, heading=2, speed=3)
    rng = np.random.default_rng(3)
    for s in states(rng, 200, 4):
        u = rng.uniform(-4.0, 4.0, 2)
        np.testing.assert_allclose(
            b_sh.filter(s, 0, u).action, a_sh.filter(s, 0, u).action, rtol=0, atol=1e-9
        )


def test_a_heading_on_the_clf_position_is_refused() -> None:
    with pytest.raises(tlshield.ShieldError, match="heading = 1"):
        shield(tlshield.AccelerationUnicycle(), heading=1)


def test_the_kinematic_bicycle_keeps_its_barriers_under_attack() -> None:
    """Full throttle and full steering at the obstacle, from 20 starts: 0 entries shielded,
    and the same attack unshielded does enter it."""
    bike = tlshield.KinematicBicycle(0.5)
    tan_max = np.tan(0.5)
    bounds = {"cbf_bounds": ([-4.0, -2 * tan_max], [4.0, 2 * tan_max])}
    sh = shield(
        bike,
        use_clf=False,
        action_bounds=([-2.0, -tan_max], [2.0, tan_max]),
        **bounds,
    )
    rng = np.random.default_rng(2)
    shielded = unshielded = 0
    for _ in range(20):
        start = np.array([rng.uniform(-1.0, 0.0), rng.uniform(-1.0, 1.0), 0.0, 1.0])
        for use_shield in (True, False):
            s = start.copy()
            for _ in range(400):
                d = OBSTACLE - s[:2]
                turn = np.clip(4.0 * np.sin(np.arctan2(d[1], d[0]) - s[2]), -tan_max, tan_max)
                a_rl = np.array([2.0, turn])
                a = sh.filter(s, 0, a_rl).action if use_shield else a_rl
                s = bike.step(s, a, 0.01)
                inside = int(np.linalg.norm(s[:2] - OBSTACLE) <= RADIUS)
                if use_shield:
                    shielded += inside
                else:
                    unshielded += inside
    assert shielded == 0
    assert unshielded > 0


def test_a_batch_of_the_wrong_width_is_refused_before_the_model_is_called() -> None:
    """The core checks a batch's rows (width, values, FSA states) before the binding evaluates
    the user's callables at them: a row of another width never reaches ``f`` or ``g``."""
    calls = []

    def counted_f(s: np.ndarray) -> np.ndarray:
        calls.append(len(s))
        return di_f(s)

    sh = shield(tlshield.ControlAffine(counted_f, di_g, state_dim=4, inputs=2))
    calls.clear()
    rng = np.random.default_rng(0)
    for width in (3, 5, 8):
        rows = rng.uniform(-1.0, 1.0, (2, width))
        expected = f"states row length: expected 4 \\(the model's state_dim\\), got {width}"
        with pytest.raises(ValueError, match=expected):
            sh.filter_batch(rows, [0, 0], np.zeros((2, 2)))
        with pytest.raises(ValueError, match=expected):
            sh.vjp_batch(rows, [0, 0], np.zeros((2, 2)), np.ones((2, 2)))
        with pytest.raises(ValueError, match=expected):
            sh.jacobian_batch(rows, [0, 0], np.zeros((2, 2)))
    bad = states(rng, 2, 4)
    bad[1, 2] = np.nan
    with pytest.raises(ValueError, match="states"):
        sh.jacobian_batch(bad, [0, 0], np.zeros((2, 2)))
    assert calls == []
    # Rows of the model's width do reach it (f at each row, and the differences of its
    # Jacobian).
    sh.filter_batch(states(rng, 2, 4), [0, 0], np.zeros((2, 2)))
    assert calls and set(calls) == {4}
