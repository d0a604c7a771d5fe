"""Spec, Halfspace and Ball from Python: results, the paper's examples, and bad input."""

from __future__ import annotations

import math
import pickle
import re

import numpy as np
import pytest

import tlshield
from tlshield.envs.channel import STATE_DIM, TASK, channel_task_spec

RUNNING_EXAMPLE = "(F a | F b) & F c & ((!a & !b) U c)"


def region(x: float) -> tlshield.Ball:
    return tlshield.Ball(pos=[0, 1], radius=1.0, center=[x, 0.0])


@pytest.fixture
def running() -> tlshield.Spec:
    return tlshield.Spec(RUNNING_EXAMPLE, {"a": region(0.0), "b": region(4.0), "c": region(8.0)})


def path(*xs: float) -> np.ndarray:
    return np.array([[x, 0.0] for x in xs])


# --- the paper's examples (Sec. III-B and the running example of Sec. V) ---------------------


def test_paper_eventually_below_four_uses_the_closed_window() -> None:
    spec = tlshield.Spec("F low", {"low": tlshield.Halfspace([-1.0], 4.0)})
    traj = np.array([[6.0], [5.0], [4.5], [3.5]])
    # max(4 - s_t) over s_0..s_3 (the paper's half-open window would stop at s_2: -0.5).
    assert spec.robustness(traj) == 0.5
    assert spec.satisfied(traj)
    assert spec.robustness(traj[:3]) == -0.5


def test_paper_running_example_c_then_a_satisfies(running: tlshield.Spec) -> None:
    traj = path(2.0, 8.0, 0.0)
    assert running.satisfied(traj)
    assert running.robustness(traj) == 1.0


def test_paper_running_example_a_before_c_violates(running: tlshield.Spec) -> None:
    traj = path(2.0, 0.0, 8.0)
    assert not running.satisfied(traj)
    assert running.robustness(traj) == -1.0


def test_paper_running_example_never_reaching_c(running: tlshield.Spec) -> None:
    traj = path(2.0, 2.5)
    # F c fails by the distance still to go: 1 - |2.5 - 8| = -4.5.
    assert running.robustness(traj) == -4.5
    assert not running.satisfied(traj)


# --- API ----------------------------------------------------------------------------------


def test_canonical_text_and_atoms() -> None:
    spec = channel_task_spec()
    assert str(spec) == TASK
    assert spec.atoms == ["g1", "g2", "g3", "c1", "c2"]
    assert str(tlshield.Spec("<> a && b", {"a": region(0), "b": region(1)})) == "F a & b"
    assert "Spec(" in repr(spec)


def test_atom_robustness_order_and_values() -> None:
    spec = channel_task_spec(half_width=1.5, goal_radius=0.5)
    s = np.zeros(STATE_DIM)
    s[:2] = [1.0, 1.5]
    s[3:9] = [1.0, 1.5, 4.0, 5.5, 0.0, 0.0]
    rho = spec.atom_robustness(s)
    assert rho.shape == (5,)
    np.testing.assert_allclose(rho, [0.5, 0.5 - 5.0, 0.5 - math.hypot(1.0, 1.5), 1.0, 2.0])


def test_predicates_value_and_gradient() -> None:
    ball = tlshield.Ball(pos=[0, 1], radius=2.0, center_dims=[2, 3])
    s = np.array([3.0, 4.0, 0.0, 0.0])
    assert ball.robustness(s) == -3.0
    np.testing.assert_allclose(ball.gradient(s), [-0.6, -0.8, 0.6, 0.8])
    np.testing.assert_array_equal(ball.gradient([1.0, 1.0, 1.0, 1.0]), np.zeros(4))
    h = tlshield.Halfspace([1.0, -1.0], 0.5)
    assert h.robustness([2, 1]) == 1.5
    np.testing.assert_array_equal(h.gradient([2, 1]), [1.0, -1.0])
    assert h.b == 0.5 and list(h.w) == [1.0, -1.0]
    assert ball.center is None and ball.center_dims == [2, 3] and ball.radius == 2.0


def test_batch_equals_single_calls_and_accepts_views() -> None:
    spec = channel_task_spec()
    rng = np.random.default_rng(0)
    trajs = rng.normal(size=(16, 30, STATE_DIM))
    expected = [spec.robustness(t) for t in trajs]
    np.testing.assert_array_equal(spec.robustness_batch(trajs), expected)
    # Non-contiguous and non-float64 inputs are converted, not rejected.
    strided = np.repeat(trajs, 2, axis=0)[::2]
    np.testing.assert_array_equal(spec.robustness_batch(strided), expected)
    np.testing.assert_array_equal(
        spec.robustness(trajs[0].astype(np.float32)),
        spec.robustness(trajs[0].astype(np.float32).astype(float)),
    )
    assert spec.robustness(trajs[0].tolist()) == expected[0]
    assert spec.robustness_batch(np.zeros((0, 5, STATE_DIM))).shape == (0,)


def test_pickle_round_trip() -> None:
    spec = channel_task_spec()
    clone = pickle.loads(pickle.dumps(spec))
    assert str(clone) == str(spec) and clone.atoms == spec.atoms
    traj = np.random.default_rng(1).normal(size=(10, STATE_DIM))
    assert clone.robustness(traj) == spec.robustness(traj)
    for p in (region(1.0), tlshield.Ball([0], 1.0, center_dims=[1]), tlshield.Halfspace([1], 2)):
        assert repr(pickle.loads(pickle.dumps(p))) == repr(p)


def test_unused_predicates_are_allowed() -> None:
    spec = tlshield.Spec("F a", {"a": region(0.0), "unused": tlshield.Halfspace([1.0] * 9, 0)})
    assert spec.atoms == ["a"]
    assert list(spec.predicates) == ["a"]
    assert spec.robustness(path(0.5)) == 0.5


def test_constants_give_infinities() -> None:
    spec = tlshield.Spec("X a", {"a": region(0.0)})
    assert spec.robustness(path(0.0)) == -math.inf
    assert tlshield.Spec("true | a", {"a": region(0.0)}).robustness(path(0.0)) == math.inf


# --- bad input ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("formula", "column", "fragment"),
    [
        ("F a &", 6, "found end of formula"),
        ("(a | b", 7, "close the `(` at column 1"),
        ("a b", 3, "after a complete formula"),
        ("a & Bad", 5, "unexpected character 'B'"),
        ("", 1, "expected an atom"),
        ("a -> ", 6, "expected an atom"),
        ("a && || b", 6, "found `|`"),
    ],
)
def test_parse_errors_name_the_column(formula: str, column: int, fragment: str) -> None:
    with pytest.raises(tlshield.SpecError) as info:
        tlshield.Spec(formula, {"a": region(0), "b": region(1)})
    message = str(info.value)
    assert f"column {column}" in message and fragment in message, message
    assert isinstance(info.value, ValueError)


@pytest.mark.parametrize(
    ("formula", "column", "fragment"),
    [
        ("G a", 1, "`G` (always) is not allowed"),
        ("[] a", 1, "`[]` (always) is not allowed"),
        ("!F a", 2, "`F` under the negation"),
        ("(F a) -> b", 2, "`F` on the left of `->`"),
        ("a U (b R a)", 8, "`R` (release)"),
        ("!(a U b)", 5, "`U` under the negation"),
    ],
)
def test_non_co_safe_formulas_are_rejected(formula: str, column: int, fragment: str) -> None:
    with pytest.raises(tlshield.SpecError, match="not an scTLTL formula") as info:
        tlshield.Spec(formula, {"a": region(0), "b": region(1)})
    assert f"column {column}" in str(info.value) and fragment in str(info.value)


def test_missing_predicates_are_named() -> None:
    with pytest.raises(tlshield.SpecError, match=r"without a predicate: b, c$"):
        tlshield.Spec("F a & (b U c)", {"a": region(0)})


@pytest.mark.parametrize(
    ("predicates", "error", "fragment"),
    [
        ({"a": "not a predicate"}, TypeError, "predicates['a']: expected a tlshield.Halfspace"),
        ({1: region(0)}, TypeError, "keys must be atom names"),
        (
            {"a": tlshield.Halfspace([1.0] * 3, 0), "b": tlshield.Halfspace([1.0] * 4, 0)},
            tlshield.SpecError,
            "disagree on the state dimension",
        ),
    ],
)
def test_bad_predicate_maps(predicates: dict, error: type, fragment: str) -> None:
    with pytest.raises(error) as info:
        tlshield.Spec("a & b", predicates)
    assert fragment in str(info.value)


def test_formula_must_be_text() -> None:
    with pytest.raises(TypeError, match="formula"):
        tlshield.Spec(b"F a", {"a": region(0)})  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("make", "fragment"),
    [
        (lambda: tlshield.Ball([0, 1], -1.0, center=[0, 0]), "radius must be finite and >= 0"),
        (lambda: tlshield.Ball([0, 1], math.nan, center=[0, 0]), "radius must be finite"),
        (lambda: tlshield.Ball([0, 1], 1.0, center=[0]), "centre has 1 entries but pos has 2"),
        (lambda: tlshield.Ball([0, -1], 1.0, center=[0, 0]), "pos[1] = -1 is not a valid"),
        (lambda: tlshield.Ball([0, 1], 1.0), "needs a centre"),
        (lambda: tlshield.Ball([0], 1.0, center=[0], center_dims=[1]), "not both"),
        (lambda: tlshield.Ball([0, 1], 1.0, center_dims=[1, 2]), "shares dimension 1"),
        (lambda: tlshield.Ball([0, 0], 1.0, center=[0, 0]), "lists dimension 0 twice"),
        (lambda: tlshield.Ball([0], 1.0, center=[math.inf]), "center[0] is inf"),
        (lambda: tlshield.Halfspace([], 1.0), "at least one entry"),
        (lambda: tlshield.Halfspace([1.0, math.nan], 1.0), "w[1] is NaN"),
        (lambda: tlshield.Halfspace([[1.0]], 1.0), "expected a 1-D array"),
    ],
)
def test_bad_predicates(make, fragment: str) -> None:
    with pytest.raises(ValueError) as info:
        make()
    assert fragment in str(info.value)


def test_bad_predicate_argument_types() -> None:
    with pytest.raises(TypeError, match="pos: expected a sequence of integer"):
        tlshield.Ball("xy", 1.0, center=[0, 0])  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="w: expected real numbers"):
        tlshield.Halfspace(["a", "b"], 1.0)
    with pytest.raises(TypeError, match="'b'"):
        tlshield.Halfspace([1.0], "b")  # type: ignore[arg-type]


def test_bad_states_for_predicates() -> None:
    ball = tlshield.Ball(pos=[0, 5], radius=1.0, center=[0, 0])
    with pytest.raises(ValueError, match="state length: expected at least 6, got 3"):
        ball.robustness([0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"s\[1\] is NaN"):
        ball.gradient([0.0, math.nan, 0, 0, 0, 0])
    h = tlshield.Halfspace([1.0, 2.0], 0.0)
    with pytest.raises(ValueError, match="expected 2, got 3"):
        h.robustness([1.0, 2.0, 3.0])


@pytest.mark.parametrize(
    ("traj", "fragment"),
    [
        (np.zeros(STATE_DIM), "traj: expected a 2-D array of shape (T+1, n), got shape (13,)"),
        (np.zeros((3, 12)), "state length: expected 13, got 12"),
        (np.zeros((0, 13)), "at least one state"),
        (np.full((2, 13), np.nan), "traj[0, 0] is NaN"),
        (np.array([[0.0] * 12 + [np.inf]] * 2), "traj[0, 12] is inf"),
    ],
)
def test_bad_trajectories(traj: np.ndarray, fragment: str) -> None:
    spec = channel_task_spec()
    with pytest.raises(ValueError) as info:
        spec.robustness(traj)
    assert fragment in str(info.value)
    with pytest.raises(ValueError, match=re.escape(fragment)):
        spec.satisfied(traj)


def test_bad_batches_and_states() -> None:
    spec = channel_task_spec()
    bad = np.zeros((4, 5, STATE_DIM))
    bad[2, 3, 1] = np.nan
    with pytest.raises(ValueError, match=r"trajs\[2, 3, 1\] is NaN"):
        spec.robustness_batch(bad)
    with pytest.raises(ValueError, match="expected a 3-D array"):
        spec.robustness_batch(np.zeros((5, STATE_DIM)))
    with pytest.raises(ValueError, match="expected 13, got 4"):
        spec.robustness_batch(np.zeros((2, 5, 4)))
    with pytest.raises(ValueError, match="expected 13, got 2"):
        spec.atom_robustness([0.0, 0.0])
    with pytest.raises(TypeError, match="traj: expected an array-like of numbers"):
        spec.robustness(None)
    with pytest.raises((TypeError, ValueError)):
        spec.robustness([["x"] * STATE_DIM])
