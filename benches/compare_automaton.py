"""The task automaton: tlshield's construction against ltlf2dfa, and its per-step work in Python.

Run from the repository root (ltlf2dfa needs the ``mona`` binary: Debian's package ``mona``)::

    .venv/bin/python benches/compare_automaton.py [--seed N] [--quick] [--json PATH]
        [--install-mona]

Two measurements on the paper's task ``(F g1 | F g2) & F g3 & (!g3 U (g1 | g2)) & ((c1 & c2)
U g3)`` over the 13-dimensional state of ``compare_robustness.py`` (same predicates, same
trajectory generator):

1. **Construction**, formula text to automaton. tlshield: ``Spec(text, predicates).automaton()``
   on a fresh ``Spec`` every time (a ``Spec`` builds its automaton once and then hands out the
   cached one, so reusing a ``Spec`` would time a cache hit; that is shown on its own row).
   ltlf2dfa: ``LTLfParser()(text).to_dfa()`` with the parser built once outside the timed
   region; ``to_dfa`` writes a MONA program, runs the ``mona`` binary in a subprocess and
   simplifies the guards with sympy into DOT text. Repeated builds in one process reuse
   sympy's cache, so the headline ltlf2dfa number is the cheaper, warm one; a build after
   ``sympy.core.cache.clear_cache()`` (what a process's first build costs, minus imports) and
   ``to_dfa(mona_dfa_out=True)`` (MONA's raw output, no sympy) are timed as well. Before
   timing, the MONA DFA and tlshield's automaton must accept the same language: a
   breadth-first walk over pairs of states, reading all 2^5 atom valuations, must never pair
   an accepting state with a rejecting one (and the pairing must be one to one).

   State counts differ only by convention: MONA's automaton has an extra state 0 that reads
   the dummy first position of its WS1S encoding (ltlf2dfa drops it and draws ``init -> 1``);
   the remaining states correspond one to one to tlshield's (initial, trap, accepting, and
   "g1 or g2 visited").

2. **Per-step FSA work** at an automaton state q (every non-accepting, non-trap state) for a
   state vector s: what an RL loop asks of the automaton every step, next state, Eq. 5A1 reward
   for leaving q and the Eq. 5C1 safe set at (s, q') for the next action. tlshield: the three
   calls ``aut.step(s, q)``, ``aut.reward(s, q, c_r)``, ``aut.safe_set(s, q')`` (0.2's fused
   ``Automaton.advance`` was removed in 0.3; in an episode loop ``Monitor.advance`` reads the
   atoms once for the step and the reward, and the shield reuses that reading). The Python
   alternative, as reference implementations of the paper do it: the five predicate robustness
   values with numpy, then the guard strings of ``aut.edges()`` (parsed once, at setup, into
   cubes of literals) evaluated in Python: the next state is the edge whose guard holds; the
   reward is ``min(rho(D_q), c_r * -rho(psi_trap))`` with the robustness of a DNF the max over
   its cubes of the min over their literals (``rho(D_q)`` alone without a trap edge); the safe
   set keeps per clause of ``aut.trap_cnf(q')`` the literal with the largest robustness (in the
   trap: of the clauses every state with a trap edge has, ``aut.recovery_cnf``). Before timing,
   both must agree on 2000 random (q, s) pairs: the same next state, the reward within 1e-12,
   the same safe-set literals with robustness within 1e-12.

   The states s are rows of the trajectory generator; half of them are "stirred" (the walker
   sometimes moved out of the channel, goal centres put near it) so that every edge of the
   automaton is taken during the check, not only the self-loops of a walk.

A tool that cannot be used (ltlf2dfa not installed, ``mona`` not on PATH) is reported and its
column left out; ``--install-mona`` lets the script ``apt-get install -y mona`` when it runs as
root without a terminal. A disagreement stops the script with exit code 1 before any timing.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import platform
import re
import shutil
import subprocess
import sys
from collections import Counter, deque
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from compare_robustness import (
    FORMULA,
    HALF_WIDTH,
    RADIUS,
    STATE_DIM,
    make_trajectories,
    measure,
    package_version,
    tlshield_spec,
)

C_R = 2.0  # reward weight of the trap term (not 1, so that a misplaced c_r shows)
PREDICATES = ("g1", "g2", "g3", "c1", "c2")  # order of predicate_values()
N_CHECK = 2000  # (q, s) pairs both per-step versions must agree on before timing
N_TIMED = 500  # distinct (q, s) pairs the per-step timings cycle through
N_TRAJ = 40  # trajectories the states s are drawn from
TOLERANCE = 1e-12
N_SHOWN = 5  # disagreements printed in full

# Ratios the tlshield columns are expected to reach.
TARGET_BUILD = 1000.0
TARGET_STEP = 20.0

Cube = tuple[tuple[int, bool, float], ...]  # literals (predicate index, positive, sign)
Dnf = tuple[Cube, ...]
SafeSet = list[tuple[str, float]]  # (literal text "g3" / "!g3", robustness)


# --------------------------------------------------------------------------------------------
# States s, predicates, and the Python per-step FSA
# --------------------------------------------------------------------------------------------


def make_pairs(rng: np.random.Generator, qs: Sequence[int], n: int) -> list[tuple[int, Any]]:
    """``n`` pairs (q, s): q uniform over ``qs``, s a trajectory row, half of them stirred.

    A stirred row first leaves the channel (|x - y| > 1.5) with probability 1/4, then each
    goal centre moves, with probability 1/2, to within 0.6 of the walker in x and y (inside
    the goal about half the time), so every atom valuation with c1 or c2 occurs.
    """
    rows = make_trajectories(rng, N_TRAJ).reshape(-1, STATE_DIM)
    states = rows[rng.integers(0, len(rows), n)].copy()
    for s in states[: n // 2]:
        if rng.random() < 0.25:
            s[0] += rng.choice([-1.0, 1.0]) * rng.uniform(1.6, 3.0)
        for k in range(3):
            if rng.random() < 0.5:
                s[3 + 2 * k : 5 + 2 * k] = s[0:2] + rng.uniform(-0.6, 0.6, 2)
    order = rng.permutation(n)
    q_of = rng.integers(0, len(qs), n)
    return [(int(qs[q_of[i]]), np.ascontiguousarray(states[j])) for i, j in enumerate(order)]


def predicate_values(s: np.ndarray) -> list[float]:
    """The five predicate robustness values at one state, in the order of ``PREDICATES``."""
    x, y = s[0], s[1]
    goals = RADIUS - np.hypot(x - s[3:8:2], y - s[4:9:2])
    c1 = x - y + HALF_WIDTH
    c2 = y - x + HALF_WIDTH
    return [*goals.tolist(), float(c1), float(c2)]


_LITERAL = re.compile(r"(!?)([a-z_][a-z0-9_]*)")


def parse_guard(text: str) -> Dnf:
    """A guard like ``g1 & !g3 | g2`` (``&`` tighter than ``|``; ``true``/``false``) as cubes."""
    text = text.strip()
    if text == "false":
        return ()
    cubes = []
    for cube_text in text.split("|"):
        cube_text = cube_text.strip()
        if cube_text == "true":
            cubes.append(())
            continue
        literals = []
        for literal_text in cube_text.split("&"):
            match = _LITERAL.fullmatch(literal_text.strip())
            if match is None or match.group(2) not in PREDICATES:
                raise ValueError(f"cannot read literal {literal_text!r} of guard {text!r}")
            positive = not match.group(1)
            literals.append((PREDICATES.index(match.group(2)), positive, 1.0 if positive else -1.0))
        cubes.append(tuple(literals))
    return tuple(cubes)


def dnf_holds(dnf: Dnf, holds: Sequence[bool]) -> bool:
    return any(all(holds[i] == positive for i, positive, _ in cube) for cube in dnf)


def dnf_rho(dnf: Dnf, rho: Sequence[float]) -> float:
    """Max over cubes of min over literals (``-rho`` for a negated one); -inf for ``false``."""
    best = -math.inf
    for cube in dnf:
        worst = math.inf
        for i, _, sign in cube:
            value = sign * rho[i]
            if value < worst:
                worst = value
        if worst > best:
            best = worst
    return best


class PythonFsa:
    """The per-step FSA work in plain Python from the guard strings of ``aut.edges()``."""

    def __init__(self, aut: Any) -> None:
        atoms = list(aut.atoms)
        if sorted(atoms) != sorted(PREDICATES):
            raise ValueError(f"automaton atoms {atoms} are not the task's {PREDICATES}")
        self.trap: int | None = aut.trap
        self.accepting = frozenset(aut.accepting)
        self.num_states = aut.num_states
        self.initial = aut.initial
        self.out: dict[int, list[tuple[int, Dnf]]] = {q: [] for q in range(self.num_states)}
        self.progress: dict[int, Dnf] = {q: () for q in range(self.num_states)}
        self.trap_guard: dict[int, Dnf | None] = dict.fromkeys(range(self.num_states))
        for src, dst, text in aut.edges():
            guard = parse_guard(text)
            self.out[src].append((dst, guard))
            if dst == self.trap and src != self.trap:
                self.trap_guard[src] = guard
            elif dst != src:
                self.progress[src] += guard
        self.cnf: dict[int, list[tuple[tuple[str, bool, int, float], ...]]] = {}
        for q in range(self.num_states):
            self.cnf[q] = [
                tuple(
                    (text, positive, PREDICATES.index(atom), 1.0 if positive else -1.0)
                    for text, atom, positive in (
                        (text, text.lstrip("!"), not text.startswith("!")) for text in clause
                    )
                )
                for clause in aut.trap_cnf(q)
            ]
        if self.trap is not None:
            # The trap keeps what every way into it kept: the clauses of the first state with a
            # trap edge that every such state has (compared as sets of literals), in its order.
            into = [self.cnf[q] for q in range(self.num_states) if q != self.trap and self.cnf[q]]
            self.cnf[self.trap] = [
                clause
                for clause in (into[0] if into else [])
                if all(set(clause) in [set(c) for c in other] for other in into[1:])
            ]

    def next_state(self, q: int, holds: Sequence[bool]) -> int:
        for dst, guard in self.out[q]:
            if dnf_holds(guard, holds):
                return dst
        raise ValueError(f"no edge out of {q} holds for {holds}")

    def evaluate(self, q: int, s: np.ndarray, c_r: float) -> tuple[int, float, SafeSet]:
        """(next state q', reward for leaving q, safe set at (s, q')): one step of the RL loop."""
        rho = predicate_values(s)
        holds = [value > 0.0 for value in rho]
        nxt = self.next_state(q, holds)
        if q in self.accepting:
            reward = 0.0
        else:
            reward = dnf_rho(self.progress[q], rho)
            trap_guard = self.trap_guard[q]
            if trap_guard is not None:
                reward = min(reward, c_r * -dnf_rho(trap_guard, rho))
        safe: SafeSet = []
        for clause in self.cnf[nxt]:
            best: tuple[str, float] | None = None
            for text, _, i, sign in clause:
                value = sign * rho[i]
                if best is None or value > best[1]:
                    best = (text, value)
            if best is not None:
                safe.append(best)
        return nxt, reward, safe

    def structure_errors(self) -> list[str]:
        """Every state's guards must partition the valuations; trap_cnf must be !trap guard."""
        errors = []
        for q in range(self.num_states):
            for bits in itertools.product((False, True), repeat=len(PREDICATES)):
                taken = [dst for dst, guard in self.out[q] if dnf_holds(guard, bits)]
                if len(taken) != 1:
                    errors.append(f"state {q}, valuation {bits}: edges to {taken} hold")
                trap_guard = self.trap_guard[q]
                trapped = trap_guard is not None and dnf_holds(trap_guard, bits)
                cnf_holds = all(
                    any(bits[i] == positive for _, positive, i, _ in clause)
                    for clause in self.cnf[q]
                )
                if q != self.trap and cnf_holds == trapped:
                    errors.append(f"state {q}, valuation {bits}: trap_cnf is not !trap guard")
        return errors


def safe_set_diff(got: SafeSet, want: SafeSet) -> float | None:
    """Max robustness difference of two safe sets, or None when their literals differ."""
    if [lit for lit, _ in got] != [lit for lit, _ in want]:
        return None
    return max((abs(v - w) for (_, v), (_, w) in zip(got, want, strict=True)), default=0.0)


def check_step(
    aut: Any, spec: Any, pyfsa: PythonFsa, pairs: Sequence[tuple[int, np.ndarray]]
) -> tuple[dict[str, float], Counter[tuple[int, int]], list[str]]:
    """Compare tlshield's step/reward/safe_set with the Python version on every pair.

    Returns the largest differences, how often each edge was taken, and the disagreements.
    """
    worst = {"atom robustness": 0.0, "reward": 0.0, "safe set robustness": 0.0}
    taken: Counter[tuple[int, int]] = Counter()
    failures: list[str] = []
    perm = [list(spec.atoms).index(name) for name in PREDICATES]
    for q, s in pairs:
        atom_rho = np.asarray(spec.atom_robustness(s))[perm]
        atom_diff = float(np.max(np.abs(atom_rho - np.array(predicate_values(s)))))
        nxt = aut.step(s, q)
        got = (nxt, aut.reward(s, q, C_R), aut.safe_set(s, nxt))
        want = pyfsa.evaluate(q, s, C_R)
        taken[(q, want[0])] += 1
        reward_diff = 0.0 if got[1] == want[1] else abs(got[1] - want[1])
        safe_diff = safe_set_diff(got[2], want[2])
        worst["atom robustness"] = max(worst["atom robustness"], atom_diff)
        worst["reward"] = max(worst["reward"], reward_diff)
        if safe_diff is not None:
            worst["safe set robustness"] = max(worst["safe set robustness"], safe_diff)
        if (
            got[0] != want[0]
            or not reward_diff <= TOLERANCE
            or safe_diff is None
            or not safe_diff <= TOLERANCE
        ):
            rho = dict(zip(PREDICATES, atom_rho.tolist(), strict=True))
            failures.append(
                f"q={q} s={s.tolist()}\n  predicate robustness {rho}"
                f"\n  tlshield (step, reward, safe_set) = {got}\n  python = {want}"
            )
    return worst, taken, failures


# --------------------------------------------------------------------------------------------
# ltlf2dfa and MONA
# --------------------------------------------------------------------------------------------


def ensure_mona(install: bool) -> tuple[str | None, str]:
    """(path of ``mona`` or None, what happened); never raises."""
    path = shutil.which("mona")
    if path is not None:
        return path, f"mona found at {path}"
    if not install:
        return None, (
            "mona is not on PATH (Debian package `mona`; pass --install-mona, as root without a"
            " terminal, to have this script apt-get install it)"
        )
    geteuid = getattr(os, "geteuid", None)
    if geteuid is None or geteuid() != 0:
        return None, "mona is not on PATH and --install-mona needs root; not installing"
    if sys.stdin is not None and sys.stdin.isatty():
        return None, "mona is not on PATH and --install-mona only runs without a terminal"
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    install_cmd = ["apt-get", "install", "-y", "mona"]
    log = []
    for commands in ([install_cmd], [["apt-get", "update"], install_cmd]):
        for cmd in commands:
            print(f"running: {' '.join(cmd)}")
            try:
                done = subprocess.run(
                    cmd,
                    env=env,
                    stdin=subprocess.DEVNULL,
                    capture_output=True,
                    text=True,
                    timeout=600,
                    check=False,
                )
            except (OSError, subprocess.SubprocessError) as err:
                log.append(f"{' '.join(cmd)}: {type(err).__name__}: {err}")
                break
            if done.returncode != 0:
                tail = (done.stderr or done.stdout).strip().splitlines()[-2:]
                log.append(f"{' '.join(cmd)} exited {done.returncode}: {' / '.join(tail)}")
                break
        path = shutil.which("mona")
        if path is not None:
            return path, f"mona installed with apt-get at {path}"
    return None, "apt-get could not install mona: " + "; ".join(log)


def mona_version() -> str | None:
    try:
        done = subprocess.run(
            ["dpkg-query", "-W", "-f=${Version}", "mona"],
            capture_output=True,
            text=True,
            timeout=30,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    if done.returncode != 0:
        return None
    return done.stdout.strip() or None


class MonaDfa:
    """MONA's DFA as ltlf2dfa's ``to_dfa(mona_dfa_out=True)`` prints it."""

    def __init__(self, text: str) -> None:
        header = re.search(r"DFA for formula with free variables:[ \t]*(.*)", text)
        accepting = re.search(r"Accepting states:[ \t]*(.*)", text)
        initial = re.search(r"Initial state:[ \t]*(\d+)", text)
        if header is None or accepting is None or initial is None:
            raise ValueError(f"not a MONA DFA: {text[:300]!r}")
        self.variables = [v.lower() for v in header.group(1).split()]
        self.accepting = {int(v) for v in accepting.group(1).split()}
        self.mona_initial = int(initial.group(1))
        self.transitions: dict[int, list[tuple[str, int]]] = {}
        for src, pattern, dst in re.findall(r"State (\d+): ([01X]+) -> state (\d+)", text):
            self.transitions.setdefault(int(src), []).append((pattern, int(dst)))
        self.num_states = len(self.transitions)
        # ltlf2dfa's convention: MONA's initial state reads the dummy first position.
        after_dummy = {dst for _, dst in self.transitions[self.mona_initial]}
        if len(after_dummy) != 1:
            raise ValueError(f"MONA's initial state has several successors: {after_dummy}")
        self.initial = after_dummy.pop()

    def step(self, state: int, holds: dict[str, bool]) -> int:
        bits = ["1" if holds[v] else "0" for v in self.variables]
        for pattern, dst in self.transitions[state]:
            if all(p in ("X", b) for p, b in zip(pattern, bits, strict=True)):
                return dst
        raise ValueError(f"MONA state {state} has no transition for {holds}")


def compare_languages(pyfsa: PythonFsa, dfa: MonaDfa) -> tuple[list[str], dict[int, int]]:
    """Walk pairs of states over every valuation; (disagreements, tlshield -> MONA state)."""
    errors: list[str] = []
    pairs = {(pyfsa.initial, dfa.initial)}
    queue = deque(pairs)
    while queue:
        q, m = queue.popleft()
        if (q in pyfsa.accepting) != (m in dfa.accepting):
            errors.append(f"tlshield state {q} and MONA state {m} disagree on acceptance")
        for bits in itertools.product((False, True), repeat=len(PREDICATES)):
            pair = (
                pyfsa.next_state(q, bits),
                dfa.step(m, dict(zip(PREDICATES, bits, strict=True))),
            )
            if pair not in pairs:
                pairs.add(pair)
                queue.append(pair)
    mapping: dict[int, int] = {}
    for q, m in sorted(pairs):
        mapping.setdefault(q, m)
    if len(pairs) != len(mapping) or len(set(mapping.values())) != len(mapping):
        errors.append(f"same language but not isomorphic: state pairs {sorted(pairs)}")
    return errors, mapping


def dot_states(dot: str) -> int:
    """Number of states drawn in ltlf2dfa's DOT text (``init`` excluded)."""
    edges = re.findall(r"^\s*(\d+)\s*->\s*(\d+)", dot, flags=re.MULTILINE)
    return len({int(v) for edge in edges for v in edge})


class Ltlf2dfa:
    """ltlf2dfa's parser and a check that it really produced a DFA (it needs ``mona``)."""

    def __init__(self, install_mona: bool) -> None:
        self.parser: Any = None
        self.version: str | None = None
        self.mona: str | None = None
        self.skipped: str | None = None
        self.install_note = ""
        try:
            from ltlf2dfa.parser.ltlf import LTLfParser
        except ImportError as err:
            self.skipped = f"ltlf2dfa cannot be imported ({type(err).__name__}: {err})"
            return
        self.version = package_version("ltlf2dfa")
        # Without mona, ltlf2dfa's to_dfa() does not fail: it returns a one-state DOT.
        path, self.install_note = ensure_mona(install_mona)
        if path is None:
            self.skipped = self.install_note
            return
        self.mona = mona_version()
        self.parser = LTLfParser()

    def build(self, text: str) -> str:
        return self.parser(text).to_dfa()

    def build_mona_only(self, text: str) -> str:
        return self.parser(text).to_dfa(mona_dfa_out=True)

    def build_cold(self, text: str) -> str:
        """``build`` after emptying sympy's cache, as the first build of a process runs."""
        from sympy.core.cache import clear_cache

        clear_cache()
        return self.build(text)


# --------------------------------------------------------------------------------------------
# Main
# --------------------------------------------------------------------------------------------


def fmt(value: float | None) -> str:
    if value is None:
        return "-"
    if value >= 100:
        return f"{value:,.0f}"
    if value >= 10:
        return f"{value:.1f}"
    if value >= 1:
        return f"{value:.2f}"
    if value >= 0.1:
        return f"{value:.3f}"
    return f"{value:.2g}"


def print_tables(
    build_ms: dict[str, float],
    step_us: dict[str, float],
    states: dict[str, int | None],
    ratios: list[tuple[str, float | None, float | None]],
    versions: dict[str, str | None],
) -> None:
    ltl = f"ltlf2dfa {versions.get('ltlf2dfa') or '(not installed)'}"
    if versions.get("mona"):
        ltl += f" (MONA {versions['mona']})"
    print("\nAutomaton construction, median ms per build (one core):\n")
    print(f"| measurement | tlshield {versions['tlshield']} | {ltl} |")
    print("|---|---:|---:|")
    print(
        "| task formula text to automaton (tlshield: `Spec(...).automaton()` on a fresh Spec;"
        " ltlf2dfa: `parser(text).to_dfa()`) | "
        f"{fmt(build_ms.get('tlshield'))} | {fmt(build_ms.get('ltlf2dfa'))} |"
    )
    print(
        "| ltlf2dfa `to_dfa()` after emptying sympy's cache (a process's first build) | - | "
        f"{fmt(build_ms.get('ltlf2dfa cold'))} |"
    )
    print(
        "| ltlf2dfa `to_dfa(mona_dfa_out=True)` (MONA's text, no sympy guards) | - | "
        f"{fmt(build_ms.get('ltlf2dfa mona only'))} |"
    )
    print(f"| tlshield `Spec(...)` alone | {fmt(build_ms.get('tlshield spec only'))} | - |")
    print(
        "| tlshield `automaton()` again on the same Spec (cached) | "
        f"{fmt(build_ms.get('tlshield cached'))} | - |"
    )
    mona_states = states.get("ltlf2dfa MONA")
    dot_count = states.get("ltlf2dfa DOT")
    ltl_states = (
        "-" if dot_count is None else f"{dot_count} (MONA: {mona_states}, with its dummy state 0)"
    )
    print(f"| states | {states['tlshield']} | {ltl_states} |")

    print("\nPer-step FSA work (next state, reward, safe set), median us per step:\n")
    print("| measurement | tlshield | Python (numpy predicates, parsed guards) |")
    print("|---|---:|---:|")
    print(
        "| step + reward + safe set (tlshield: 3 calls; Python: predicates once, then guards) | "
        f"{fmt(step_us.get('tlshield'))} | {fmt(step_us.get('python'))} |"
    )
    print(
        f"| next state only | {fmt(step_us.get('tlshield step'))} | "
        f"{fmt(step_us.get('python predicates + next state'))} (with the predicates) |"
    )
    print(f"| reward only | {fmt(step_us.get('tlshield reward'))} | - |")
    print(f"| safe set only | {fmt(step_us.get('tlshield safe_set'))} | - |")
    print(f"| the five predicates with numpy | - | {fmt(step_us.get('python predicates'))} |")

    print("\n| tlshield speedup | value | target | |")
    print("|---|---:|---:|---|")
    for label, value, target in ratios:
        if target is None:
            status, shown_target = "info", "-"
        else:
            shown_target = f">= {target:g}x"
            status = "n/a" if value is None else ("ok" if value >= target else "BELOW TARGET")
        shown = "-" if value is None else f"{value:,.1f}x"
        print(f"| {label} | {shown} | {shown_target} | {status} |")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0, help="seed of the states s (default 0)")
    parser.add_argument("--quick", action="store_true", help="fewer repetitions (smoke run)")
    parser.add_argument("--json", metavar="PATH", help="also write the numbers to PATH")
    parser.add_argument(
        "--install-mona",
        action="store_true",
        help="apt-get install -y mona when it is missing (only as root, without a terminal)",
    )
    args = parser.parse_args(argv)
    budget = 0.6 if args.quick else 4.0  # seconds per measurement, roughly
    ltl_reps = 3 if args.quick else 10  # at least this many ltlf2dfa builds (mona, sympy)

    try:
        import tlshield

        spec = tlshield_spec(FORMULA)
        aut = spec.automaton()
    except (ImportError, AttributeError) as err:
        print(f"ERROR: tlshield's automaton is not available ({err})", file=sys.stderr)
        return 1
    versions: dict[str, str | None] = {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "tlshield": tlshield.__version__,
    }
    print(f"formula: {FORMULA}")
    print(f"tlshield: {aut!r}")
    for src, dst, guard in aut.edges():
        print(f"  {src} -> {dst}: {guard}")

    # --- agreement: the Python per-step FSA against tlshield --------------------------------
    pyfsa = PythonFsa(aut)
    structure = pyfsa.structure_errors()
    if structure:
        print("ERROR: tlshield's guards or trap CNFs are inconsistent:", file=sys.stderr)
        for line in structure[:N_SHOWN]:
            print(f"  {line}", file=sys.stderr)
        return 1
    qs = [q for q in range(aut.num_states) if q != aut.trap and q not in pyfsa.accepting]
    rng = np.random.default_rng(args.seed)
    check_pairs = make_pairs(rng, qs, N_CHECK)
    timed_pairs = make_pairs(rng, qs, N_TIMED)
    worst, taken, failures = check_step(aut, spec, pyfsa, check_pairs)
    edges_out = {(src, dst) for src, dst, _ in aut.edges() if src in qs}
    print(
        f"\nper-step check, {N_CHECK} (q, s) pairs, q in {qs}, seed {args.seed}, c_r = {C_R:g}:"
        f" edges taken {dict(sorted(taken.items()))}"
    )
    if set(taken) != edges_out:
        print(f"note: edges never taken in the check: {sorted(edges_out - set(taken))}")
    for name, diff in worst.items():
        print(f"max |tlshield - python| {name}: {diff:.3g}")
    if failures:
        print(
            f"ERROR: {len(failures)} of {N_CHECK} pairs disagree (next state, reward within"
            f" {TOLERANCE:g}, or safe set); the first {min(N_SHOWN, len(failures))}:",
            file=sys.stderr,
        )
        for line in failures[:N_SHOWN]:
            print(line, file=sys.stderr)
        return 1
    print(f"all {N_CHECK} pairs agree")

    # --- agreement: ltlf2dfa's DFA against tlshield's automaton ---------------------------
    ltl = Ltlf2dfa(args.install_mona)
    versions["ltlf2dfa"] = ltl.version
    versions["mona"] = ltl.mona
    states: dict[str, int | None] = {"tlshield": aut.num_states}
    mapping: dict[int, int] = {}
    if ltl.skipped is None:
        print(
            f"\nltlf2dfa {ltl.version}: {ltl.install_note};"
            f" it parses the task as {ltl.parser(FORMULA)}"
        )
        try:
            dfa = MonaDfa(ltl.build_mona_only(FORMULA))
            dot = ltl.build(FORMULA)
        except Exception as err:  # a broken mona or ltlf2dfa must not stop the script
            ltl.skipped = f"ltlf2dfa failed on the task ({type(err).__name__}: {err})"
        else:
            states["ltlf2dfa MONA"] = dfa.num_states
            states["ltlf2dfa DOT"] = dot_states(dot)
            errors, mapping = compare_languages(pyfsa, dfa)
            if errors:
                print("ERROR: ltlf2dfa's DFA and tlshield's automaton differ:", file=sys.stderr)
                for line in errors[:N_SHOWN]:
                    print(f"  {line}", file=sys.stderr)
                return 1
            print(
                f"same language as tlshield's automaton; states tlshield -> MONA {mapping};"
                f" MONA has {dfa.num_states} states (its state {dfa.mona_initial} only reads the"
                f" dummy first position), ltlf2dfa's DOT draws {states['ltlf2dfa DOT']}"
            )
    if ltl.skipped is not None:
        print(f"\nltlf2dfa column skipped: {ltl.skipped}")

    # --- timing: construction ---------------------------------------------------------------
    build_ms: dict[str, float] = {}
    runs: dict[str, dict[str, int]] = {}

    def timed(label: str, fn: Callable[[Any], object], items: Sequence[Any], reps: int) -> float:
        median, blocks, inner = measure(fn, items, budget, reps)
        runs[label] = {"blocks": blocks, "calls_per_block": inner}
        return median

    build_ms["tlshield"] = (
        timed("build tlshield", lambda _: tlshield_spec(FORMULA).automaton(), [None], 5) * 1e3
    )
    build_ms["tlshield spec only"] = (
        timed("build tlshield spec only", lambda _: tlshield_spec(FORMULA), [None], 5) * 1e3
    )
    build_ms["tlshield cached"] = (
        timed("build tlshield cached", lambda _: spec.automaton(), [None], 5) * 1e3
    )
    if ltl.skipped is None:
        builds = {
            "ltlf2dfa": ltl.build,
            "ltlf2dfa cold": ltl.build_cold,
            "ltlf2dfa mona only": ltl.build_mona_only,
        }
        for label, build in builds.items():
            build_ms[label] = (
                timed(f"build {label}", lambda _, b=build: b(FORMULA), [None], ltl_reps) * 1e3
            )

    # --- timing: per step -------------------------------------------------------------------
    def tlshield_separate(item: tuple[int, np.ndarray]) -> object:
        q, s = item
        nxt = aut.step(s, q)
        return nxt, aut.reward(s, q, C_R), aut.safe_set(s, nxt)

    def python_next(item: tuple[int, np.ndarray]) -> object:
        q, s = item
        return pyfsa.next_state(q, [value > 0.0 for value in predicate_values(s)])

    plans: dict[str, Callable[[Any], object]] = {
        "tlshield": tlshield_separate,
        "python": lambda item: pyfsa.evaluate(item[0], item[1], C_R),
        "tlshield step": lambda item: aut.step(item[1], item[0]),
        "tlshield reward": lambda item: aut.reward(item[1], item[0], C_R),
        "tlshield safe_set": lambda item: aut.safe_set(item[1], item[0]),
        "python predicates + next state": python_next,
        "python predicates": lambda item: predicate_values(item[1]),
    }
    step_us = {
        label: timed(f"step {label}", fn, timed_pairs, 5) * 1e6 for label, fn in plans.items()
    }

    def ratio(slow: float | None, fast: float | None) -> float | None:
        return None if slow is None or fast is None else slow / fast

    ratios: list[tuple[str, float | None, float | None]] = [
        (
            "construction: tlshield vs ltlf2dfa `to_dfa()`",
            ratio(build_ms.get("ltlf2dfa"), build_ms["tlshield"]),
            TARGET_BUILD,
        ),
        (
            "construction: tlshield vs ltlf2dfa `to_dfa()`, sympy's cache emptied",
            ratio(build_ms.get("ltlf2dfa cold"), build_ms["tlshield"]),
            None,
        ),
        (
            "construction: tlshield vs ltlf2dfa `to_dfa(mona_dfa_out=True)`",
            ratio(build_ms.get("ltlf2dfa mona only"), build_ms["tlshield"]),
            None,
        ),
        (
            "per step: tlshield step + reward + safe_set (3 calls) vs Python",
            ratio(step_us["python"], step_us["tlshield"]),
            TARGET_STEP,
        ),
    ]
    print_tables(build_ms, step_us, states, ratios, versions)
    if ltl.skipped is not None:
        print(f"\nltlf2dfa skipped: {ltl.skipped}")

    if args.json:
        report = {
            "formula": FORMULA,
            "seed": args.seed,
            "quick": args.quick,
            "c_r": C_R,
            "check_pairs": N_CHECK,
            "timed_pairs": N_TIMED,
            "automaton_states": list(qs),
            "edges_taken_in_check": {f"{q}->{d}": n for (q, d), n in sorted(taken.items())},
            "max_abs_diff_vs_tlshield": worst,
            "num_states": states,
            "tlshield_to_mona_states": {str(q): m for q, m in mapping.items()},
            "build_ms": build_ms,
            "step_us": step_us,
            "speedups": {label: {"value": v, "target": t} for label, v, t in ratios},
            "runs": runs,
            "skipped": {"ltlf2dfa": ltl.skipped} if ltl.skipped else {},
            "versions": versions,
        }
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(report, fh, indent=2)
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
