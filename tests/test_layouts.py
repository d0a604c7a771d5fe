"""Every array argument of the native API gives the C-order answer in every numpy layout, and
refuses what is not an array of real numbers with an error that names it (issue 20, point 1).

The functions under test are not listed by hand: they are every method of ``_core.pyi`` with an
``ArrayLike`` parameter. Each needs a recipe in :data:`CASES` (an object and C-order float64
arguments); a new array-taking method without one fails
:func:`test_every_array_parameter_has_a_case`.

``python -m tests.test_layouts`` prints the layout matrix (functions x layouts).
"""

from __future__ import annotations

import ast
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import tlshield
from tlshield import _core
from tlshield.envs.channel import ChannelEnv, channel_task_spec
from tlshield.envs.point_mass import PointMassEnv

STUB = Path(_core.__file__).with_name("_core.pyi")


def array_parameters() -> dict[str, list[str]]:
    """``{"Class.method": [parameter, ...]}`` for every stub method with an ArrayLike
    parameter (``ArrayLike | None`` included)."""
    found: dict[str, list[str]] = {}
    for node in ast.parse(STUB.read_text()).body:
        if not isinstance(node, ast.ClassDef):
            continue
        for item in node.body:
            if not isinstance(item, ast.FunctionDef):
                continue
            args = item.args.args + item.args.kwonlyargs
            names = [
                a.arg
                for a in args
                if a.annotation is not None
                # An array (ControlAffine's f, g: a callable returning one, or the array).
                and "ArrayLike" in ast.unparse(a.annotation).replace("], ArrayLike]", "]")
            ]
            if names:
                found[f"{node.name}.{item.name}"] = names
    return found


def _states(count: int) -> np.ndarray:
    """Real Channel-v0 states (13 values), some near goals and walls."""
    env = ChannelEnv(config="rl")
    env.reset(seed=3)
    rng = np.random.default_rng(3)
    out = []
    while len(out) < count:
        out.append(env.unwrapped.state.copy())
        _, _, term, trunc, _ = env.step(rng.uniform(-1, 1, size=2))
        if term or trunc:
            env.reset(seed=len(out))
    return np.array(out)


STATES = _states(48)
S = STATES[5]
SPEC = channel_task_spec()
AUT = SPEC.automaton()
Q = AUT.step(S, AUT.initial)
QS = np.array([AUT.step(s, AUT.initial) for s in STATES], dtype=np.int64)
RNG = np.random.default_rng(11)
A_RL = RNG.uniform(-1, 1, size=(len(STATES), 2)) * [1.0, 2.0]
DRIFT = RNG.normal(scale=0.3, size=STATES.shape) * (np.arange(13) >= 9)
UNICYCLE = tlshield.Unicycle(0.1)
F, G = UNICYCLE.eval(S)


def _shield() -> tlshield.Shield:
    return tlshield.Shield(
        SPEC,
        UNICYCLE,
        alpha=2.0,
        c3=1.0,
        k=1e4,
        cbf_bounds=((-1.5, -3.0), (1.5, 3.0)),
        clf_bounds=((-0.3, -0.6), (0.3, 0.6)),
        barriers={
            "!o1": tlshield.Avoid(tlshield.Ball(pos=[0, 1], radius=0.45, center_dims=[9, 10]))
        },
    )


@dataclass
class Case:
    """How to call one method: ``target`` makes the object (or is the class, for
    constructors), ``args`` are the C-order float64 (or int64 state) arguments by name."""

    target: Callable[[], Any]
    method: str
    args: dict[str, Any]


def _model(cls: type, *a: Any) -> Callable[[], Any]:
    return lambda: cls(*a)


def _bicycle_f(s: np.ndarray) -> np.ndarray:
    return np.array([s[3] * np.cos(s[2]), s[3] * np.sin(s[2]), 0.0, 0.0])


def _bicycle_g(s: np.ndarray) -> np.ndarray:
    return np.array([[0.0, 0.0], [0.0, 0.0], [0.0, s[3] / 0.5], [1.0, 0.0]])


def _control_affine() -> Any:
    return _core.ControlAffine(_bicycle_f, _bicycle_g, state_dim=4, inputs=2)


TRAJ = STATES[:12]
DYN_S = np.arange(1.0, 14.0) / 4


def _region(kind: Any) -> Any:
    """A union or intersection of a moving ball, a fixed one and a half-space."""
    return kind(
        [
            tlshield.Ball([0, 1], 0.7, center_dims=[3, 4]),
            tlshield.Ball([0, 1], 0.9, center=S[5:7]),
            tlshield.Halfspace(S[:13], 0.5),
        ]
    )


def _started_monitor() -> Any:
    """A monitor of the task one step into an episode (so that ``advance`` has a past)."""
    monitor = _core.Monitor(AUT, AUT.progress_reward())
    monitor.reset(STATES[0])
    return monitor


def _world_reset() -> Any:
    """``reset(s0, obstacles)`` of a Channel-v0 world, returning what it then holds."""
    world = ChannelEnv(config="rl_cbf_clf")._world

    def reset(s0: Any, obstacles: Any) -> Any:
        world.reset(s0, obstacles)
        return world.state, world.drift

    return reset


def _world_step() -> Any:
    """A shielded Channel-v0 world one reset into an episode, as ``step(action)``."""
    env = ChannelEnv(config="rl_cbf_clf")
    env.reset(seed=3)
    return lambda action: env._world.step(action, env.tracker.monitor, env.shield)


def _point_mass_reset() -> Any:
    """``reset(s0)`` of a PointMass-v0 world, returning the state it then holds."""
    world = PointMassEnv()._world

    def reset(s0: Any) -> Any:
        world.reset(s0)
        return world.state

    return reset


def _point_mass_step() -> Any:
    """A shielded PointMass-v0 world one reset into an episode, as ``step(a_rl)``."""
    env = PointMassEnv()
    env.reset(seed=3)
    return lambda a_rl: env._world.step(a_rl, env.tracker.monitor, env.shield)


def _started_batch() -> Any:
    """A batch of four monitors one step into their episodes."""
    batch = _core.MonitorBatch(AUT, 4, AUT.progress_reward())
    batch.reset(STATES[:4])
    return batch


CASES: dict[str, Case] = {
    "Halfspace.__new__": Case(lambda: tlshield.Halfspace, "__call__", {"w": S[:4], "b": 0.5}),
    "Halfspace.robustness": Case(lambda: tlshield.Halfspace(S[:13], 0.5), "robustness", {"s": S}),
    "Halfspace.gradient": Case(lambda: tlshield.Halfspace(S[:13], 0.5), "gradient", {"s": S}),
    "Ball.__new__": Case(
        lambda: tlshield.Ball,
        "__call__",
        {"pos": [0, 1], "radius": 0.7, "center": S[3:5], "heading": 2, "offset": S[5:7]},
    ),
    "Ball.robustness": Case(
        lambda: tlshield.Ball([0, 1], 0.7, center_dims=[3, 4]), "robustness", {"s": S}
    ),
    "Ball.gradient": Case(
        lambda: tlshield.Ball([0, 1], 0.7, center_dims=[3, 4]), "gradient", {"s": S}
    ),
    "Union.robustness": Case(lambda: _region(tlshield.Union), "robustness", {"s": S}),
    "Union.gradient": Case(lambda: _region(tlshield.Union), "gradient", {"s": S}),
    "Intersection.robustness": Case(lambda: _region(tlshield.Intersection), "robustness", {"s": S}),
    "Intersection.gradient": Case(lambda: _region(tlshield.Intersection), "gradient", {"s": S}),
    "Spec.atom_robustness": Case(lambda: SPEC, "atom_robustness", {"s": S}),
    "Spec.robustness": Case(lambda: SPEC, "robustness", {"traj": TRAJ}),
    "Spec.satisfied": Case(lambda: SPEC, "satisfied", {"traj": TRAJ}),
    "Spec.robustness_batch": Case(
        lambda: SPEC, "robustness_batch", {"trajs": STATES[:40].reshape(4, 10, 13)}
    ),
    "Automaton.step": Case(lambda: AUT, "step", {"q": Q, "s": S}),
    "Automaton.step_batch": Case(lambda: AUT, "step_batch", {"qs": QS, "states": STATES}),
    "Automaton.run": Case(lambda: AUT, "run", {"traj": TRAJ}),
    "Automaton.accepts": Case(lambda: AUT, "accepts", {"traj": TRAJ}),
    "Automaton.reward": Case(
        lambda: AUT, "reward", {"q": Q, "s_next": S, "c_r": 1.0, "trap_penalty": -10.0}
    ),
    "Automaton.safe_set": Case(lambda: AUT, "safe_set", {"q": Q, "s": S}),
    "Automaton.goal": Case(lambda: AUT, "goal", {"q": Q, "s": S}),
    "ProgressReward.potential": Case(lambda: AUT.progress_reward(), "potential", {"q": Q, "s": S}),
    **{
        f"{name}.{method}": Case(
            _model(cls, *ctor),
            method,
            {"s": DYN_S, **({"a": DYN_S[:inputs], "dt": 0.1} if method == "step" else {})},
        )
        for name, cls, ctor, inputs in (
            ("Unicycle", tlshield.Unicycle, (0.1,), 2),
            ("SingleIntegrator", tlshield.SingleIntegrator, ([0, 1],), 2),
            ("DoubleIntegrator", tlshield.DoubleIntegrator, ([0, 1], [2, 3]), 2),
            ("AccelerationUnicycle", _core.AccelerationUnicycle, (), 2),
            ("KinematicBicycle", _core.KinematicBicycle, (0.5,), 2),
            ("ThrustTurn", _core.ThrustTurn, (2.8, 2.9, 1.9), 2),
        )
        for method in ("eval", "step")
    },
    "ControlAffine.__new__": Case(
        lambda: _core.ControlAffine,
        "__call__",
        {
            # Constant parts: a drift, an input matrix moving dimensions 2 and 3, a Jacobian.
            "f": DYN_S[:4],
            "g": np.array([[0.0, 0.0], [0.0, 0.0], [0.5, 0.0], [0.0, 2.0]]),
            "state_dim": 4,
            "inputs": 2,
            "jacobian": np.triu(np.ones((4, 4)), 1),
            "probe": STATES[:3, :4] - 1.0,
        },
    ),
    "ControlAffine.eval": Case(_control_affine, "eval", {"s": DYN_S[:4]}),
    "ControlAffine.drift_jacobian": Case(_control_affine, "drift_jacobian", {"s": DYN_S[:4]}),
    "ControlAffine.step": Case(
        _control_affine, "step", {"s": DYN_S[:4], "a": DYN_S[:2], "dt": 0.1}
    ),
    "Shield.filter": Case(
        _shield,
        "filter",
        {"s": S, "q": Q, "a_rl": A_RL[5], "f": F, "g": G, "drift": DRIFT[5]},
    ),
    "Shield.problem": Case(
        _shield,
        "problem",
        {"s": S, "q": Q, "a_rl": A_RL[5], "f": F, "g": G, "drift": DRIFT[5]},
    ),
    "Shield.barrier_values": Case(_shield, "barrier_values", {"s": S}),
    "Shield.filter_monitor": Case(
        _shield,
        "filter_monitor",
        {"monitor": _started_monitor(), "a_rl": A_RL[0], "f": F, "g": G, "drift": DRIFT[0]},
    ),
    "Shield.filter_monitors": Case(
        _shield,
        "filter_monitors",
        {"monitors": _started_batch(), "a_rl": A_RL[:4], "drift": DRIFT[:4]},
    ),
    "Shield.filter_batch": Case(
        _shield, "filter_batch", {"states": STATES, "qs": QS, "a_rl": A_RL, "drift": DRIFT}
    ),
    "Shield.vjp_batch": Case(
        _shield,
        "vjp_batch",
        {"states": STATES, "qs": QS, "a_rl": A_RL, "grad_action": A_RL[::-1], "drift": DRIFT},
    ),
    "Shield.jacobian_batch": Case(
        _shield, "jacobian_batch", {"states": STATES, "qs": QS, "a_rl": A_RL, "drift": DRIFT}
    ),
    "Monitor.reset": Case(lambda: _core.Monitor(AUT, AUT.progress_reward()), "reset", {"s0": S}),
    "Monitor.advance": Case(_started_monitor, "advance", {"s_next": S}),
    "MonitorBatch.reset": Case(
        lambda: _core.MonitorBatch(AUT, 4),
        "reset",
        {"states": STATES[:4], "rows": np.array([2, 0, 3, 1])},
    ),
    "MonitorBatch.advance": Case(_started_batch, "advance", {"states": STATES[4:8]}),
    "ChannelWorld.rl_action": Case(
        lambda: ChannelEnv(config="rl")._world, "rl_action", {"action": A_RL[:6] / 2}
    ),
    "ChannelWorld.reset": Case(
        _world_reset,
        "__call__",
        {"s0": S, "obstacles": np.array([[4.0, 1.0, 0.3, 0.5], [6.0, 0.9, 0.2, 2.0]])},
    ),
    "ChannelWorld.step": Case(_world_step, "__call__", {"action": A_RL[5] / 4}),
    "PointMassWorld.reset": Case(
        _point_mass_reset, "__call__", {"s0": np.array([1.5, 1.0, 0.25, -0.5])}
    ),
    "PointMassWorld.step": Case(_point_mass_step, "__call__", {"a_rl": A_RL[5] / 4}),
}


#: Integer parameters (FSA states); every other ArrayLike parameter holds real numbers.
INTEGER_PARAMS = {"qs", "rows"}


def _flip_view(x: np.ndarray) -> np.ndarray:
    """A view with negative strides on every axis holding the values of ``x``."""
    flipped = np.ascontiguousarray(np.flip(x))
    return np.flip(flipped)


def _strided(x: np.ndarray) -> np.ndarray:
    """A non-contiguous view (every other element of the last axis) holding ``x``."""
    big = np.zeros((*x.shape[:-1], 2 * x.shape[-1]), dtype=x.dtype)
    big[..., ::2] = x
    return big[..., ::2]


def _readonly(x: np.ndarray) -> np.ndarray:
    y = x.copy()
    y.flags.writeable = False
    return y


#: Layouts of a real-valued argument: name -> C-order float64 array -> the argument.
REAL_LAYOUTS: dict[str, Callable[[np.ndarray], Any]] = {
    "C": lambda x: x,
    "Fortran": np.asfortranarray,
    "T.copy().T": lambda x: x.T.copy().T,
    "strided": _strided,
    "negative strides": _flip_view,
    "read-only": _readonly,
    "float32": lambda x: x.astype(np.float32),
    "int64": lambda x: np.round(x).astype(np.int64),
    "list": lambda x: x.tolist(),
}

#: Layouts of an FSA-state argument.
INT_LAYOUTS: dict[str, Callable[[np.ndarray], Any]] = {
    "C": lambda x: x,
    "strided": _strided,
    "negative strides": _flip_view,
    "read-only": _readonly,
    "int32": lambda x: x.astype(np.int32),
    "uint8": lambda x: x.astype(np.uint8),
    "list": lambda x: x.tolist(),
}


def _call(key: str, **override: Any) -> Any:
    case = CASES[key]
    target = case.target()
    fn = target if case.method == "__call__" else getattr(target, case.method)
    return fn(**{**case.args, **override})


def canon(value: Any) -> Any:
    """A comparable form of any result: arrays and scalars as float arrays, results by field."""
    results = (
        _core.FilterResult,
        _core.FilterBatch,
        _core.TaskStep,
        _core.TaskBatch,
        _core.WorldStep,
    )
    if isinstance(value, results):
        names = [n for n in dir(value) if not n.startswith("_")]
        return {n: canon(getattr(value, n)) for n in names}
    if isinstance(value, _core.Halfspace):
        return canon((value.w, value.b))
    if isinstance(value, _core.Ball):
        return canon((value.pos, value.radius, value.center, value.heading, value.offset))
    if isinstance(value, _core.ControlAffine):
        return canon((value.actuated, value.integrated))
    if isinstance(value, (tuple, list)):
        return [canon(v) for v in value]
    if isinstance(value, dict):
        return {k: canon(v) for k, v in value.items()}
    if isinstance(value, (str, type(None))):
        return value
    return np.asarray(value, dtype=np.float64).tolist()


def _reference(arg: Any, integer: bool) -> np.ndarray:
    """The C-order array of exactly the values a layout variant holds."""
    return np.ascontiguousarray(np.asarray(arg), dtype=np.int64 if integer else np.float64)


def matrix() -> dict[str, dict[str, bool]]:
    """``{"Class.method(param)": {layout: agrees with the C-order answer}}``."""
    rows: dict[str, dict[str, bool]] = {}
    for key, params in array_parameters().items():
        for param in params:
            base = CASES[key].args[param]
            integer = param in INTEGER_PARAMS
            layouts = INT_LAYOUTS if integer else REAL_LAYOUTS
            row = {}
            for layout, make in layouts.items():
                arg = make(np.asarray(base))
                want = canon(_call(key, **{param: _reference(arg, integer)}))
                row[layout] = canon(_call(key, **{param: arg})) == want
            rows[f"{key}({param})"] = row
    return rows


def test_every_array_parameter_has_a_case() -> None:
    found = array_parameters()
    assert len(found) >= 25, found  # the stub parser still sees the API
    missing = {k: v for k, v in found.items() if k not in CASES}
    assert not missing, f"array-taking methods without a layout case: {missing}"
    for key, params in found.items():
        absent = [p for p in params if p not in CASES[key].args]
        assert not absent, f"{key}: no C-order argument for {absent}"
    # Every public class of the native module with array methods is in the stub walk.
    runtime = {name for name in dir(_core) if isinstance(getattr(_core, name), type)}
    assert {k.split(".")[0] for k in found} <= runtime


PAIRS = [(key, param) for key, params in array_parameters().items() for param in params]


@pytest.mark.parametrize(("key", "param"), PAIRS, ids=[f"{k}({p})" for k, p in PAIRS])
def test_every_layout_gives_the_c_order_answer(key: str, param: str) -> None:
    base = np.asarray(CASES[key].args[param])
    integer = param in INTEGER_PARAMS
    layouts = INT_LAYOUTS if integer else REAL_LAYOUTS
    for layout, make in layouts.items():
        arg = make(base)
        want = canon(_call(key, **{param: _reference(arg, integer)}))
        got = canon(_call(key, **{param: arg}))
        assert got == want, f"{key}({param}) in layout {layout!r} differs from C order"
    # The variants really are the layouts they claim (the test would be vacuous otherwise).
    if base.ndim == 2:
        assert np.asfortranarray(base).flags.f_contiguous
        assert not np.asfortranarray(base).flags.c_contiguous
    assert _flip_view(base).strides[0] < 0


def _names(message: str, param: str) -> bool:
    return re.search(rf"(^|\W){re.escape(param)}(\W|$)", message) is not None


def _bad_inputs(base: np.ndarray, integer: bool) -> dict[str, Any]:
    bad: dict[str, Any] = {
        "complex": base.astype(np.complex128) + 0.5j,
        "object": base.astype(object),
        "boolean": base > 0,
        "one axis too many": base[None, ...],
        "text": base.astype(str),
    }
    if base.ndim > 1:
        bad["one axis too few"] = base[0]
    if integer:
        bad["float states"] = base.astype(np.float64)
    return bad


@pytest.mark.parametrize(("key", "param"), PAIRS, ids=[f"{k}({p})" for k, p in PAIRS])
def test_bad_arrays_are_refused_naming_the_argument(key: str, param: str) -> None:
    base = np.asarray(CASES[key].args[param])
    for what, arg in _bad_inputs(base, param in INTEGER_PARAMS).items():
        with pytest.raises((TypeError, ValueError)) as err:
            _call(key, **{param: arg})
        assert _names(str(err.value), param), f"{key}({param}), {what}: {err.value}"
        if what in ("complex", "object", "boolean", "text", "float states"):
            assert err.type is TypeError or issubclass(err.type, TypeError), (what, err.value)


def test_fsa_states_must_be_integers_in_range() -> None:
    for bad, kind in ((1.0, TypeError), (True, TypeError), ("0", TypeError)):
        with pytest.raises(kind, match="q"):
            AUT.step(S, bad)
    for bad in (-1, AUT.num_states, 10**30, -(10**30)):
        with pytest.raises(ValueError, match=r"q: state -?\d+ does not exist"):
            AUT.step(S, bad)
        with pytest.raises(ValueError, match="q: state"):
            _shield().filter(S, bad, A_RL[0])
    assert AUT.step(S, np.int16(Q)) == AUT.step(S, Q)
    with pytest.raises(ValueError, match=r"qs\[1\]: state 18446744073709551615"):
        AUT.step_batch(STATES[:2], np.array([0, 2**64 - 1], dtype=np.uint64))


def test_robustness_is_finite_up_to_1e300() -> None:
    ball = tlshield.Ball([0, 1], 1.0, center=[0.0, 0.0])
    moving = tlshield.Ball([0, 1], 1.0, center_dims=[2, 3])
    half = tlshield.Halfspace([1.0, -1.0, 0.0, 0.0], 0.5)
    spec = tlshield.Spec("F a & F b & !c U a", {"a": ball, "b": moving, "c": half})
    for scale in (1e150, 1e154, 1e200, 1e300):
        s = np.array([scale, -scale, -scale, scale])
        assert np.isfinite(ball.robustness(s)) and np.isfinite(moving.robustness(s))
        assert ball.robustness(s) == pytest.approx(1.0 - np.hypot(scale, scale))
        assert moving.robustness(s) == pytest.approx(1.0 - 2 * np.hypot(scale, scale))
        assert np.isfinite(spec.atom_robustness(s)).all()
        traj = np.array([s, -s, s / 2])
        assert np.isfinite(spec.robustness(traj))
        assert np.isfinite(spec.robustness_batch(traj[None])).all()
        assert np.isfinite(ball.gradient(s)).all()


if __name__ == "__main__":
    rows = matrix()
    layouts = list(REAL_LAYOUTS)
    print("| function(argument) | " + " | ".join(layouts) + " |")
    print("|---|" + "---|" * len(layouts))
    for name, row in rows.items():
        cells = [("ok" if row[lay] else "**WRONG**") if lay in row else "n/a" for lay in layouts]
        print(f"| `{name}` | " + " | ".join(cells) + " |")
    pairs = [v for row in rows.values() for v in row.values()]
    print(f"\n{sum(pairs)} of {len(pairs)} (function, argument, layout) triples agree with C order")
