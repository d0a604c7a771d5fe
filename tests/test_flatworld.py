"""Tasks written elsewhere (issue 22): FlatWorld-v0 as published, region predicates, exclusive
groups checked against the geometry, rank-aware goals, the progress-preserving safe set and the
reward's loopholes (training and the benchmark: tests/lab/test_flatworld_benchmark.py)."""

from __future__ import annotations

import math
import pickle
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import tlshield
from tlshield.envs.flatworld import CIRCLES, COLOURS, FORMULAS, colour_predicates, flatworld_spec

ID = "tlshield/FlatWorld-v0"
F2 = "F(orange & (!red U magenta))"


def _inside(colour: str, p: np.ndarray) -> bool:
    return any(math.dist(p, c) < r for c, r, name in CIRCLES if name == colour)


def test_map_and_colours_as_published() -> None:
    assert len(CIRCLES) == 9
    assert COLOURS == ("red", "magenta", "yellow", "orange", "blue", "green", "aqua")
    preds = colour_predicates()
    assert isinstance(preds["red"], list) and len(preds["red"]) == 2
    spec = flatworld_spec("F red & F green")
    assert isinstance(spec.predicates["red"], tlshield.Union)
    # A colour holds strictly inside any of its discs.
    for p in ([-1.4, 0.55], [0.5, -1.3], [0.0, 2.0]):
        rho = spec.predicates["red"].robustness(p)
        assert (rho > 0) == _inside("red", np.array(p))


@pytest.mark.parametrize("config", ["rl", "rl_cbf_clf"])
def test_check_env_and_render(config: str) -> None:
    env = gym.make(ID, formula=FORMULAS[3], config=config, render_mode="rgb_array")
    check_env(env.unwrapped)
    check_env(env, skip_render_check=True)
    env.reset(seed=3)
    env.step(np.array([0.5, -0.5]))
    frame = env.render()
    assert isinstance(frame, np.ndarray) and frame.ndim == 3 and frame.shape[2] == 3


def test_bad_settings_are_refused_where_given() -> None:
    with pytest.raises(tlshield.SpecError, match="purple"):
        gym.make(ID, formula="F purple")
    with pytest.raises(TypeError, match="unknown FlatWorld-v0 parameter"):
        gym.make(ID, speed=2.0)
    with pytest.raises(ValueError, match="step_size"):
        gym.make(ID, step_size=-0.1)


def test_unions_and_intersections() -> None:
    a = tlshield.Ball([0, 1], 0.6, center=[-0.5, 0.0])
    b = tlshield.Ball([0, 1], 0.5, center=[0.4, 0.2])
    u, i = tlshield.Union([a, b]), tlshield.Intersection([a, b])
    rng = np.random.default_rng(0)
    for s in rng.uniform(-2, 2, size=(50, 2)):
        assert u.robustness(s) == max(a.robustness(s), b.robustness(s))
        assert i.robustness(s) == min(a.robustness(s), b.robustness(s))
    assert pickle.loads(pickle.dumps(u)).robustness([0.1, 0.1]) == u.robustness([0.1, 0.1])
    assert "Union([Ball(" in repr(u) and len(i.parts) == 2
    # A list is a union wherever a predicate is expected.
    spec = tlshield.Spec("F x", {"x": [a, b]})
    assert spec.predicates["x"].robustness([0.4, 0.2]) == u.robustness([0.4, 0.2])
    with pytest.raises(TypeError, match=r"predicates\['x'\]\[1\]"):
        tlshield.Spec("F x", {"x": [a, "b"]})
    with pytest.raises(tlshield.SpecError, match="at least one part"):
        tlshield.Union([])


def test_exclusive_groups_are_checked_against_the_geometry() -> None:
    preds = colour_predicates()
    with pytest.raises(tlshield.SpecError, match=r'"red" and "magenta".*overlap'):
        tlshield.Spec("F red & F magenta", preds, exclusive=[["red", "magenta"]])
    with pytest.raises(tlshield.SpecError, match="not an atom"):
        tlshield.Spec("F red", preds, exclusive=[["red", "purple"]])
    ok = tlshield.Spec("F orange & F red", preds, exclusive=[["orange", "red"]])
    assert ok.exclusive == [["orange", "red"]]
    # Unreachable acceptance is an error at construction, not ranks of None.
    with pytest.raises(ValueError, match="no path to acceptance"):
        gym.make(ID, formula="F(orange & red)")


def test_rank_aware_goal_and_progress_safe_set_on_formula_2_as_written() -> None:
    spec = flatworld_spec(F2)
    aut = spec.automaton()
    q = aut.step([-1.53, -0.5], aut.step([-1.9, -0.5], aut.initial))  # into orange
    assert aut.ranks[q] == 1 and aut.ranks[aut.initial] == 2
    goal = aut.goal([-1.53, -0.5], q)
    assert goal is not None and _inside("magenta", goal)
    assert aut.safe_set([-1.53, -0.5], q) == []  # Eq. 5C1: no trap, nothing kept
    kept = dict(aut.safe_set([-1.53, -0.5], q, preserve_progress=True))
    assert kept.get("!red", 0.0) > 0.0


@pytest.mark.parametrize("policy", ["zero", "random"])
def test_formula_2_as_written_is_done_without_entering_red_after_orange(policy: str) -> None:
    env = gym.make(ID, formula=F2, config="rl_cbf_clf")
    rng = np.random.default_rng(1)
    for episode in range(10):
        env.reset(seed=10_000 + episode)
        seen_orange = False
        for _ in range(500):
            a = np.zeros(2) if policy == "zero" else rng.uniform(-1, 1, 2)
            _, _, term, trunc, info = env.step(a)
            p = env.unwrapped.state
            seen_orange = seen_orange or _inside("orange", p)
            assert not (seen_orange and _inside("red", p) and not _inside("magenta", p))
            assert not info["box_exit"]
            if term or trunc:
                break
        assert info["success"], f"episode {episode}"


def test_shield_info_carries_goal_barriers_slack_and_solver() -> None:
    env = gym.make(ID, formula=FORMULAS[3], config="rl_cbf_clf")
    env.reset(seed=5)
    _, _, _, _, info = env.step(np.zeros(2))
    shield = info["shield"]
    assert {"goal", "barriers", "slack", "solver", "status", "a_cbf", "a_clf"} <= set(shield)
    assert shield["goal"] is not None and shield["slack"] == 0.0
    assert shield["solver"] in (tlshield.Solver.ACTIVE_SET, tlshield.Solver.CLARABEL)
    assert {"x<size", "x>-size", "y<size", "y>-size"} <= set(shield["barriers"])
    # Safe sets name each literal once (formula 4's first state had duplicate rows).
    aut = flatworld_spec(FORMULAS[3]).automaton()
    for s in np.random.default_rng(2).uniform(-2, 2, size=(30, 2)):
        for q in range(aut.num_states):
            for progress in (False, True):
                names = [n for n, _ in aut.safe_set(s, q, preserve_progress=progress)]
                assert len(names) == len(set(names))


def _return(config: str, policy: Any, seed: int = 10_003, gamma: float = 0.99) -> float:
    env = gym.make(ID, formula="F yellow", config=config)
    env.reset(seed=seed)
    total, discount = 0.0, 1.0
    for _ in range(500):
        _, r, term, trunc, _ = env.step(policy(env))
        total += discount * float(r)
        discount *= gamma
        if term or trunc:
            break
    return total


def test_no_reward_loophole_finish_beats_dawdling_beats_leaving() -> None:
    yellow = np.array([-1.0, -1.2])

    def finish(env: Any) -> np.ndarray:
        return np.clip((yellow - env.unwrapped.state) / 0.08, -1, 1)

    def dawdle(env: Any) -> np.ndarray:
        return np.zeros(2)

    def leave(env: Any) -> np.ndarray:
        return np.array([1.0, 1.0])

    finished, dawdled, left = (_return("rl", p) for p in (finish, dawdle, leave))
    assert finished > dawdled > left, (finished, dawdled, left)
