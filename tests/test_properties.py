"""Property tests: the Rust core against the pure-Python reference in tests/reference.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import tlshield

from .reference import ball, halfspace, robustness, satisfied, to_text

ATOMS = ["p", "q", "r", "near"]
AXES = [np.eye(3)[k] for k in range(3)]
RUST_PREDICATES = {
    "p": tlshield.Halfspace(AXES[0], 0.0),
    "q": tlshield.Halfspace(AXES[1], -0.5),
    "r": tlshield.Halfspace(AXES[2], 0.25),
    "near": tlshield.Ball(pos=[0, 1], radius=1.0, center=[0.5, -0.5]),
}
REFERENCE_PREDICATES = {
    "p": halfspace(AXES[0], 0.0),
    "q": halfspace(AXES[1], -0.5),
    "r": halfspace(AXES[2], 0.25),
    "near": ball([0, 1], 1.0, np.array([0.5, -0.5])),
}

leaves = st.one_of(
    st.sampled_from(ATOMS).map(lambda a: ("atom", a)),
    st.sampled_from([("true",), ("false",)]),
)

propositional = st.recursive(
    leaves,
    lambda inner: st.one_of(
        inner.map(lambda a: ("not", a)),
        st.tuples(st.sampled_from(["and", "or", "implies"]), inner, inner),
    ),
    max_leaves=6,
)

co_safe = st.recursive(
    propositional,
    lambda inner: st.one_of(
        propositional.map(lambda a: ("not", a)),
        st.tuples(st.sampled_from(["and", "or", "until"]), inner, inner),
        st.tuples(st.just("implies"), propositional, inner),
        st.tuples(st.sampled_from(["F", "X"]), inner),
    ),
    max_leaves=8,
)

values = st.one_of(
    st.sampled_from([-1.0, -0.5, 0.0, 0.25, 0.5, 1.0]),
    st.floats(-3.0, 3.0, allow_nan=False),
)
trajectories = st.integers(1, 7).flatmap(lambda n: arrays(np.float64, (n, 3), elements=values))


def same(a: float, b: float) -> bool:
    return a == b or math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-12)


@settings(max_examples=1500, deadline=None)
@given(co_safe, trajectories)
def test_robustness_matches_reference(formula: tuple, traj: np.ndarray) -> None:
    spec = tlshield.Spec(to_text(formula), RUST_PREDICATES)
    rho = spec.robustness(traj)
    expected = robustness(formula, traj, REFERENCE_PREDICATES)
    assert same(rho, expected), (str(spec), rho, expected)
    sat = spec.satisfied(traj)
    assert sat == satisfied(formula, traj, REFERENCE_PREDICATES)
    if rho > 0:
        assert sat
    if rho < 0:
        assert not sat


@settings(max_examples=200, deadline=None)
@given(co_safe, st.integers(0, 5), st.integers(1, 6), st.data())
def test_batch_matches_single(formula: tuple, batch: int, steps: int, data) -> None:
    trajs = data.draw(arrays(np.float64, (batch, steps, 3), elements=values))
    spec = tlshield.Spec(to_text(formula), RUST_PREDICATES)
    out = spec.robustness_batch(trajs)
    assert out.shape == (batch,)
    for b in range(batch):
        assert out[b] == spec.robustness(trajs[b])


@settings(max_examples=300, deadline=None)
@given(co_safe)
def test_canonical_text_is_a_fixed_point(formula: tuple) -> None:
    spec = tlshield.Spec(to_text(formula), RUST_PREDICATES)
    again = tlshield.Spec(str(spec), RUST_PREDICATES)
    assert str(again) == str(spec)


def _parse_or_reject(text: str) -> None:
    try:
        tlshield.Spec(text, RUST_PREDICATES)
    except tlshield.SpecError as err:
        assert str(err)


@settings(max_examples=2000, deadline=None)
@given(st.binary(max_size=64))
def test_random_bytes_never_crash_the_parser(raw: bytes) -> None:
    _parse_or_reject(raw.decode("utf-8", errors="replace"))
    _parse_or_reject(raw.decode("latin-1"))


@settings(max_examples=2000, deadline=None)
@given(st.text(alphabet="pqr near()!&|-><=[]FXGURW truefalse\t\n", max_size=48))
def test_formula_like_text_never_crashes_the_parser(text: str) -> None:
    _parse_or_reject(text)


@pytest.mark.parametrize("depth", [10, 100, 1000, 100_000])
def test_deep_nesting_is_rejected_not_a_crash(depth: int) -> None:
    text = "(" * depth + "p" + ")" * depth
    if depth <= 100:
        assert str(tlshield.Spec(text, RUST_PREDICATES)) == "p"
    else:
        with pytest.raises(tlshield.SpecError, match="nests too deeply"):
            tlshield.Spec(text, RUST_PREDICATES)
