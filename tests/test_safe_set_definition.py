"""The default safe set (the progress-preserving one, ``Automaton.avoid_cnf``) against its
definition, letter by letter (issue 57, item 6: the shield reference read it from the core and
never checked it). For a formula alone every letter can occur, so the definition needs no
geometry: ``rank(q)`` is the fewest transitions from ``q`` to acceptance (BFS over every letter
and the automaton's edges), and a letter satisfies the avoid CNF of ``q`` exactly when no edge
from ``q`` that it takes leads to a state farther from acceptance or from which acceptance is
unreachable; where ``q`` itself cannot reach acceptance, exactly when it takes no edge into
the trap. Random co-safe formulas (hypothesis) and the paper's task."""

from __future__ import annotations

import itertools

from hypothesis import given, settings
from hypothesis import strategies as st

import tlshield
from tests.shield_reference import literal, parse_guard

ATOMS = ("a", "b", "c")


def formulas() -> st.SearchStrategy[str]:
    leaf = st.sampled_from([*ATOMS, *(f"!{a}" for a in ATOMS)])

    def grow(inner: st.SearchStrategy[str]) -> st.SearchStrategy[str]:
        return st.one_of(
            inner.map(lambda f: f"F ({f})"),
            inner.map(lambda f: f"X ({f})"),
            st.tuples(inner, inner).map(lambda p: f"({p[0]}) U ({p[1]})"),
            st.tuples(inner, inner).map(lambda p: f"({p[0]}) & ({p[1]})"),
            st.tuples(inner, inner).map(lambda p: f"({p[0]}) | ({p[1]})"),
        )

    return st.recursive(leaf, grow, max_leaves=5)


def holds(cubes: list, letter: tuple[bool, ...]) -> bool:
    return any(all(letter[a] == pos for a, pos in cube) for cube in cubes)


def check(automaton: tlshield.Automaton) -> None:
    atoms = automaton.atoms
    n, states = len(atoms), automaton.num_states
    letters = list(itertools.product([False, True], repeat=n))
    edges = [(src, dst, parse_guard(g, atoms)) for src, dst, g in automaton.edges()]

    def successor(q: int, letter: tuple[bool, ...]) -> int:
        taken = [dst for src, dst, cubes in edges if src == q and holds(cubes, letter)]
        assert len(taken) == 1, (q, letter, taken)  # deterministic and complete
        return taken[0]

    # Ranks by BFS, independently of the core's.
    rank: list[int | None] = [0 if q in automaton.accepting else None for q in range(states)]
    changed = True
    while changed:
        changed = False
        for q in range(states):
            nxt = [rank[successor(q, letter)] for letter in letters]
            best = min((r for r in nxt if r is not None), default=None)
            if rank[q] is None and best is not None and q not in automaton.accepting:
                rank[q] = best + 1
                changed = True
            elif rank[q] is not None and best is not None and best + 1 < rank[q]:
                rank[q] = best + 1
                changed = True
    assert automaton.ranks == rank, (automaton.ranks, rank)

    for q in range(states):
        cnf = [[literal(text) for text in clause] for clause in automaton.avoid_cnf(q)]
        for letter in letters:
            truth = dict(zip(atoms, letter, strict=True))
            kept = all(any(truth[a] == pos for a, pos in clause) for clause in cnf)
            dst = successor(q, letter)
            if rank[q] is None:
                setback = dst == automaton.trap and q != automaton.trap
            else:
                setback = dst != q and (rank[dst] is None or rank[dst] > rank[q])
            assert kept == (not setback), (q, letter, dst, automaton.avoid_cnf(q))


@settings(max_examples=60, deadline=None)
@given(formulas())
def test_the_avoid_cnf_is_its_definition_on_random_formulas(formula: str) -> None:
    check(tlshield.Automaton.from_formula(formula))


def test_the_avoid_cnf_is_its_definition_on_the_papers_task() -> None:
    from tlshield.envs.channel_task import TASK, TASK_WITH_OBSTACLES

    for formula in (TASK, TASK_WITH_OBSTACLES):
        check(tlshield.Automaton.from_formula(formula))
