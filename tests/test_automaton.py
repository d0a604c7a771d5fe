"""Automaton from Python: the paper's examples, properties against the reference, bad input."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import tlshield
from tests.shield_reference import literal
from tlshield.envs.channel import STATE_DIM, channel_task_spec

from .reference import satisfied, to_text
from .test_properties import REFERENCE_PREDICATES, RUST_PREDICATES, co_safe, values


def region(x: float) -> tlshield.Ball:
    return tlshield.Ball(pos=[0, 1], radius=1.0, center=[x, 0.0])


@pytest.fixture
def running() -> tlshield.Automaton:
    spec = tlshield.Spec(
        "(F a | F b) & F c & ((!a & !b) U c)",
        {"a": region(0.0), "b": region(4.0), "c": region(8.0)},
    )
    return spec.automaton()


@pytest.fixture
def task() -> tlshield.Automaton:
    return channel_task_spec(half_width=1.5, goal_radius=0.5).automaton()


def test_running_example_structure(running: tlshield.Automaton) -> None:
    # Paper Fig. 5.1: q0 --c--> q1 --(a | b)--> qf, trap when a or b come before c.
    assert (running.num_states, running.initial, running.trap) == (4, 0, 1)
    assert running.accepting == [3]
    assert running.edges() == [
        (0, 0, "!a & !b & !c"),
        (0, 1, "a & !c | b & !c"),
        (0, 2, "!a & !b & c"),
        (0, 3, "a & c | b & c"),
        (1, 1, "true"),
        (2, 2, "!a & !b"),
        (2, 3, "a | b"),
        (3, 3, "true"),
    ]
    assert running.trap_cnf(0) == [["!a", "c"], ["!b", "c"]]
    assert running.trap_cnf(2) == []


def test_running_example_safe_set_and_reward(running: tlshield.Automaton) -> None:
    s = np.array([2.0, 0.0])  # between a and b, far from c
    # The paper's C(s, q0) = {!a, !b}.
    assert running.safe_set(s, 0) == [("!a", 1.0), ("!b", 1.0)]
    assert running.safe_set(s, 2) == []
    # rho(D_q0) = -5 (c is 5 beyond reach); rho(!psi_trap) = 1; min(-5, 2 * 1).
    assert running.reward(s, 0, 2.0) == -5.0
    # Inside a: D_q0 = -6.5; negated trap guard -0.5 -> c_r = 20 makes it -10.
    assert running.reward([0.5, 0.0], 0, 20.0) == -10.0
    assert running.reward(s, 2, 2.0) == -1.0  # rho(a | b), no trap edge
    assert running.reward(s, 3, 2.0) == 0.0  # accepting
    assert running.reward(s, 1, 2.0, trap_penalty=-7.0) == -7.0


def test_running_example_runs(running: tlshield.Automaton) -> None:
    good = np.array([[2.0, 0.0], [8.0, 0.0], [0.0, 0.0]])
    bad = np.array([[2.0, 0.0], [0.0, 0.0], [8.0, 0.0]])
    assert running.run(good) == 3 and running.accepts(good)
    assert running.run(bad) == 1 and not running.accepts(bad)
    q0 = running.step(good[0], running.initial)
    assert running.step(good[1], q0) == 2


def test_task_automaton(task: tlshield.Automaton) -> None:
    assert (task.num_states, task.initial, task.trap, task.accepting) == (4, 0, 1, [2])
    assert task.atoms == ["g1", "g2", "g3", "c1", "c2"]
    assert (0, 3, "g1 & !g3 & c1 & c2 | g2 & !g3 & c1 & c2") in task.edges()
    assert (3, 2, "g3") in task.edges()
    assert task.trap_cnf(0) == [["g3", "c1"], ["g3", "c2"], ["g1", "g2", "!g3"]]


def test_task_safe_set_near_the_channel_border(task: tlshield.Automaton) -> None:
    s = np.zeros(STATE_DIM)
    s[1] = 1.4  # x = 0, y = 1.4: c1 = 0.1 (close to the border), c2 = 2.9
    s[3:9] = [3.0, 3.0, 5.0, 4.0, 8.0, 8.0]
    kept = task.safe_set(s, 0)
    assert [lit for lit, _ in kept] == ["c1", "c2", "!g3"]
    np.testing.assert_allclose([v for _, v in kept], [0.1, 2.9, math.hypot(8.0, 6.6) - 0.5])
    # Reward at the same point: D_q0 is led by reaching g1 (rho(g1) = 0.5 - |(0,1.4)-(3,3)|).
    d_q0 = max(
        min(0.5 - math.hypot(3, 1.6), 0.5 - math.hypot(8, 6.6)),  # g1 & g3
        min(0.5 - math.hypot(3, 1.6), -(0.5 - math.hypot(8, 6.6)), 0.1, 2.9),  # g1 & !g3 & ...
        min(0.5 - math.hypot(5, 2.6), -(0.5 - math.hypot(8, 6.6)), 0.1, 2.9),
    )
    assert task.reward(s, 0, 1.0) == pytest.approx(min(d_q0, 0.1))


def test_dot_and_pickle(task: tlshield.Automaton) -> None:
    dot = task.to_dot()
    assert dot.startswith("digraph fsa {") and "doublecircle" in dot and "trap" in dot
    clone = pickle.loads(pickle.dumps(task))
    assert clone.edges() == task.edges()
    assert "trap=1" in repr(task)


def test_step_batch_equals_step(task: tlshield.Automaton) -> None:
    rng = np.random.default_rng(3)
    states = rng.normal(scale=2.0, size=(64, STATE_DIM))
    qs = rng.integers(0, task.num_states, size=64)
    out = task.step_batch(states, qs)
    assert out.dtype == np.int64
    assert out.tolist() == [task.step(s, int(q)) for q, s in zip(qs, states, strict=True)]


@settings(max_examples=600, deadline=None)
@given(co_safe, st.integers(1, 7).flatmap(lambda n: arrays(np.float64, (n, 3), elements=values)))
def test_acceptance_matches_reference(formula: tuple, traj: np.ndarray) -> None:
    aut = tlshield.Spec(to_text(formula), RUST_PREDICATES).automaton()
    assert aut.accepts(traj) == satisfied(formula, traj, REFERENCE_PREDICATES)


def signed(rho: dict[str, float], text: str) -> float:
    """The robustness of a literal's text (``"!a"``) given the atoms' robustness."""
    atom, positive = literal(text)
    return rho[atom] if positive else -rho[atom]


@settings(max_examples=300, deadline=None)
@given(co_safe, arrays(np.float64, (3,), elements=values), st.floats(0.1, 10.0))
def test_reward_is_eq_5a1(formula: tuple, s: np.ndarray, c_r: float) -> None:
    aut = tlshield.Spec(to_text(formula), RUST_PREDICATES).automaton()
    spec = aut.spec
    rho = dict(zip(spec.atoms, spec.atom_robustness(s), strict=True))

    def dnf(guard: str) -> float:
        if guard == "false":
            return -math.inf
        if guard == "true":
            return math.inf
        return max(
            min(signed(rho, lit) for lit in cube.split(" & ")) for cube in guard.split(" | ")
        )

    for q in range(aut.num_states):
        if q == aut.trap:
            continue
        if q in aut.accepting:
            assert aut.reward(s, q, c_r) == 0.0
            continue
        progress = [g for src, dst, g in aut.edges() if src == q and dst not in (q, aut.trap)]
        expected = max(dnf(g) for g in progress)
        clauses = aut.trap_cnf(q)
        if clauses:
            cnf = min(max(signed(rho, lit) for lit in c) for c in clauses)
            expected = min(expected, c_r * cnf)
            # The kept literal is the clause's first most robust one (Eq. 5C1 with argmax),
            # each literal once (two clauses may keep the same one).
            picks = [max(c, key=lambda lit: signed(rho, lit)) for c in clauses]
            once = list(dict.fromkeys(picks))
            assert aut.safe_set(s, q) == [(lit, signed(rho, lit)) for lit in once]
        assert aut.reward(s, q, c_r) == pytest.approx(expected, rel=1e-12, abs=1e-12)


# --- bad input ----------------------------------------------------------------------------


def test_bad_state_ids(task: tlshield.Automaton) -> None:
    s = np.zeros(STATE_DIM)
    for q in (-1, 4, 10**6):
        with pytest.raises(ValueError, match=rf"q: state {q} does not exist \(the automaton"):
            task.step(s, q)
        with pytest.raises(ValueError, match="does not exist"):
            task.reward(s, q, 1.0)
        with pytest.raises(ValueError, match="does not exist"):
            task.safe_set(s, q)
        with pytest.raises(ValueError, match="does not exist"):
            task.trap_cnf(q)
    with pytest.raises(ValueError, match=r"qs\[1\]: state 9 does not exist"):
        task.step_batch(np.zeros((2, STATE_DIM)), [0, 9])
    with pytest.raises(TypeError, match="q: expected an integer FSA state"):
        task.step(s, 1.5)  # type: ignore[arg-type]


def test_bad_vectors(task: tlshield.Automaton) -> None:
    with pytest.raises(ValueError, match="state length: expected 13, got 3"):
        task.step([0.0, 0.0, 0.0], 0)
    with pytest.raises(ValueError, match=r"s\[2\] is NaN"):
        task.safe_set([0.0, 0.0, math.nan] + [0.0] * 10, 0)
    with pytest.raises(ValueError, match=r"is inf"):
        task.reward([math.inf] + [0.0] * 12, 0, 1.0)
    with pytest.raises(ValueError, match="expected 3 rows to match qs, got 2"):
        task.step_batch(np.zeros((2, STATE_DIM)), [0, 0, 0])
    with pytest.raises(ValueError, match=r"states\[1, 0\] is NaN"):
        task.step_batch(np.array([[0.0] * 13, [math.nan] + [0.0] * 12]), [0, 0])
    with pytest.raises(ValueError, match="expected a 2-D array"):
        task.run(np.zeros(STATE_DIM))
    with pytest.raises(ValueError, match="c_r: expected a finite weight > 0"):
        task.reward(np.zeros(STATE_DIM), 0, 0.0)
    with pytest.raises(ValueError, match="trap state, which has no task reward"):
        task.reward(np.zeros(STATE_DIM), task.trap, 1.0)
    with pytest.raises(ValueError, match="trap_penalty is NaN"):
        task.reward(np.zeros(STATE_DIM), task.trap, 1.0, trap_penalty=math.nan)


def test_too_many_atoms() -> None:
    names = [f"p{i}" for i in range(31)]
    spec = tlshield.Spec(" | ".join(f"F {n}" for n in names), dict.fromkeys(names, region(0)))
    with pytest.raises(ValueError, match="31 atoms; automata support at most 30"):
        spec.automaton()


def test_many_atoms_build_what_the_formula_needs() -> None:
    """24 atoms in a sequence: 25 states and a diagram of a few dozen nodes, never 2^24 of
    anything (issue 24); steps walk the diagram and accept the sequence, one atom a step."""
    names = [f"p{i}" for i in range(24)]
    text = "F(" + " & F(".join(names) + ")" * len(names)
    centres = {n: region(3.0 * i) for i, n in enumerate(names)}
    aut = tlshield.Spec(text, centres).automaton()
    assert aut.num_states == 25
    assert aut.diagram_nodes < 25 * 24
    q = aut.initial
    for i in range(24):
        assert q not in aut.accepting
        q = aut.step(np.array([3.0 * i, 0.0]), q)
    assert q in aut.accepting


# --- command line -------------------------------------------------------------------------


def test_the_deprecated_advance_methods_are_gone() -> None:
    """``Automaton.advance`` and ``ProgressReward.advance`` (deprecated in 0.2 for ``Monitor``)
    were removed in 0.3."""
    aut = channel_task_spec().automaton()
    assert not hasattr(aut, "advance")
    assert not hasattr(aut.progress_reward(), "advance")


def test_an_automaton_from_a_formula_alone() -> None:
    task = channel_task_spec().automaton()
    alone = tlshield.Automaton.from_formula(str(task.spec))
    assert alone.edges() == task.edges() and alone.trap_cnf(0) == task.trap_cnf(0)
    assert (alone.initial, alone.trap, alone.accepting) == (task.initial, task.trap, task.accepting)
    assert alone.to_dot() == task.to_dot()
    with pytest.raises(ValueError, match="a formula alone"):
        alone.step(np.zeros(STATE_DIM), 0)
    with pytest.raises(tlshield.ShieldError, match="formula alone"):
        tlshield.Shield(
            alone,
            tlshield.Unicycle(0.1),
            alpha=1.0,
            c3=1.0,
            k=1.0,
            cbf_bounds=(-1.0, 1.0),
            clf_bounds=(-1.0, 1.0),
        )
    with pytest.raises(tlshield.SpecError, match="`G` \\(always\\) is not allowed"):
        tlshield.Automaton.from_formula("G a")


def test_the_old_argument_order_is_refused(task: tlshield.Automaton) -> None:
    """0.1 took ``(q, s)``; every call now takes the state first, like ``Shield.filter``. A call
    in the old order is an error about the argument in the wrong place, never a wrong answer."""
    s = np.zeros(STATE_DIM)
    progress = task.progress_reward()
    calls = {
        "step": lambda: task.step(0, s),  # type: ignore[arg-type]
        "reward": lambda: task.reward(0, s, 1.0),  # type: ignore[arg-type]
        "safe_set": lambda: task.safe_set(0, s),  # type: ignore[arg-type]
        "goal": lambda: task.goal(0, s),  # type: ignore[arg-type]
        "potential": lambda: progress.potential(0, s),  # type: ignore[arg-type]
        "step_batch": lambda: task.step_batch([0], s[None]),
    }
    for name, call in calls.items():
        with pytest.raises((TypeError, ValueError), match=r"\bs\b|states|\bq\b|qs") as err:
            call()
        assert "0.1" not in str(err.value), name
