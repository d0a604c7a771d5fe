"""A barrier's side is stated by its type (issue 57, the first slip): ``Avoid(p)`` keeps the
state out of ``p``'s region and ``Inside(p)`` keeps it in, whatever the barrier is called. A bare
predicate, which used to mean "inside" unless its name began with "!", is refused with the fix;
the old "!" spelling still means "outside" for one release, with a DeprecationWarning."""

from __future__ import annotations

import copy
import pickle
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import tlshield

SHELF = tlshield.Ball([0, 1], 0.5, center=[1.5, 0.0])
GAINS = {"alpha": 2.0, "c3": 1.0, "k": 1e4, "cbf_bounds": (-4.0, 4.0), "clf_bounds": (-1.0, 1.0)}


def shield(barriers: object) -> tlshield.Shield:
    spec = tlshield.Spec("F g", {"g": tlshield.Ball([0, 1], 0.3, center=[3.0, 0.0])})
    return tlshield.Shield(spec, tlshield.SingleIntegrator([0, 1]), barriers=barriers, **GAINS)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("barriers", "where"),
    [
        ({"shelf": SHELF}, 'barriers["shelf"]'),
        ({"shelf": (SHELF, 0.5)}, 'barriers["shelf"]'),
        ([SHELF], "barriers[0]"),
        ({"arena": tlshield.Halfspace([1.0, 0.0], 2.0)}, 'barriers["arena"]'),
    ],
)
def test_a_bare_predicate_is_refused_with_the_fix(barriers: object, where: str) -> None:
    # The slip: "shelf" without "!" meant "stay inside", and drove the robot in.
    with pytest.raises(ValueError, match=r"Avoid\(predicate\).*Inside\(predicate\)") as err:
        shield(barriers)
    assert str(err.value).startswith(where)


def test_inside_under_a_bang_name_is_a_contradiction() -> None:
    with pytest.raises(ValueError, match=r'barriers\["!shelf"\]: Inside\(\.\.\.\) under a name'):
        shield({"!shelf": tlshield.Inside(SHELF)})


def test_the_old_bang_spelling_warns_and_still_means_outside() -> None:
    s = np.array([0.0, 0.0])
    with pytest.warns(DeprecationWarning, match=r'barriers\["!shelf"\].*tlshield.Avoid'):
        old = shield({"!shelf": SHELF})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        new = shield({"!shelf": tlshield.Avoid(SHELF)})
    h = dict(old.filter(s, 0, [1.0, 0.0]).barriers)["!shelf"]
    assert h == pytest.approx(1.0) == dict(new.filter(s, 0, [1.0, 0.0]).barriers)["!shelf"]


@pytest.mark.parametrize("name", ["shelf", "!shelf", "h0"])
def test_the_side_is_the_types_whatever_the_name(name: str) -> None:
    s = np.array([0.0, 0.0])
    out = dict(shield({name: tlshield.Avoid(SHELF)}).filter(s, 0, [0.0, 0.0]).barriers)
    assert out[name] == pytest.approx(-SHELF.robustness(s))
    if not name.startswith("!"):
        inside = dict(shield({name: tlshield.Inside(SHELF)}).filter(s, 0, [0.0, 0.0]).barriers)
        assert inside[name] == pytest.approx(SHELF.robustness(s))


@settings(max_examples=60, deadline=None)
@given(
    x=st.floats(-2.0, 0.9),
    y=st.floats(-1.5, 1.5),
    push=st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0)),
)
def test_avoid_keeps_a_robot_pushed_at_the_shelf_out_of_it(
    x: float, y: float, push: tuple[float, float]
) -> None:
    # The warehouse slip, with the side stated: a robot outside the shelf, pushed anywhere,
    # is never driven in (the single integrator's step under the shield's own model).
    sh = shield({"shelf": tlshield.Avoid(SHELF)})
    s = np.array([x, y])
    if SHELF.robustness(s) > -0.05:
        return
    dt = 0.01
    for _ in range(40):
        a = sh.filter(s, 0, [1.0 + push[0], push[1]]).action
        s = s + dt * a
        assert SHELF.robustness(s) <= 0.0


def test_sides_are_values() -> None:
    a, b = tlshield.Avoid(SHELF), tlshield.Inside([SHELF, SHELF])
    assert a == tlshield.Avoid(SHELF) and a != tlshield.Inside(SHELF)
    assert repr(a).startswith("Avoid(Ball(") and isinstance(b.predicate, tlshield.Union)
    for twin in (copy.deepcopy(a), pickle.loads(pickle.dumps(a))):
        assert twin == a
    with pytest.raises(TypeError, match=r"Avoid\(predicate\): expected a tlshield.Halfspace"):
        tlshield.Avoid(1.0)  # type: ignore[arg-type]


def test_a_shield_pickles_its_sides_under_any_name() -> None:
    # 0.3 refused to pickle an outside barrier not named "!...": the side is now the type's.
    sh = shield({"shelf": (tlshield.Avoid(SHELF), 0.5), "arena": tlshield.Inside(SHELF)})
    s = np.array([1.0, 0.4])
    want = sh.filter(s, 0, [1.0, 0.0])
    for twin in (copy.deepcopy(sh), pickle.loads(pickle.dumps(sh))):
        got = twin.filter(s, 0, [1.0, 0.0])
        assert got.barriers == want.barriers and np.array_equal(got.action, want.action)
