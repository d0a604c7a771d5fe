"""The paper's shield step written the way a Python user would: numpy for the predicates,
dynamics and constraint rows, and a QP solver from Python (cvxpy with Parameters built once,
or clarabel's own Python API with the problem set up once and its data updated per step).

Independent of the Rust core except for the automaton's structure (its trap CNFs and edge
guards, read once as text). Used as the reference in tests/test_shield.py and as the baseline in
benches/compare_shield.py.

The QP (DESIGN.md, Eq. 5D2), for the case study's unicycle reference point:
    min |a_cbf|^2 + |a_clf|^2 + K d
    s.t. -Lg h_i . (a_cbf + a_clf) <= Lf h_i + Lg h_i . a_rl + alpha (h_i - margin)  (barriers)
         Lg V . a_clf - d <= -(Lf V + Lg V . a_rl + c3 V) + delta_0,  d >= 0
         box bounds on a_cbf, a_clf
with delta = delta_0 + d, delta_0 = max(0, min over the CLF box of the CLF row's residual).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

Cube = list[tuple[int, bool]]  # (atom index, positive)


def parse_guard(text: str, atoms: Sequence[str]) -> list[Cube]:
    """``"a & !b | c"`` -> [[(a, True), (b, False)], [(c, True)]]."""
    if text.strip() == "true":
        return [[]]
    cubes = []
    for part in text.split("|"):
        cube = []
        for lit in part.split("&"):
            lit = lit.strip()
            positive = not lit.startswith("!")
            cube.append((atoms.index(lit.lstrip("!")), positive))
        cubes.append(cube)
    return cubes


def literal(text: str) -> tuple[str, bool]:
    """A literal's text as tlshield encodes it: ``"!g3"`` -> ``("g3", False)``."""
    return (text[1:], False) if text.startswith("!") else (text, True)


@dataclass(frozen=True)
class Task:
    """The case study's predicates: three goal balls (centres in the state), two channel
    half-spaces, over the 13-dimensional state of tlshield.envs.channel."""

    half_width: float = 1.5
    goal_radius: float = 0.5
    eps: float = 0.1

    def atoms(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Robustness of g1, g2, g3, c1, c2 at s and their gradients (5, 13)."""
        rho = np.empty(5)
        grad = np.zeros((5, s.shape[0]))
        p = s[:2]
        for k in range(3):
            c = s[3 + 2 * k : 5 + 2 * k]
            diff = p - c
            dist = float(np.hypot(diff[0], diff[1]))
            rho[k] = self.goal_radius - dist
            if dist > 0.0:
                unit = diff / dist
                grad[k, :2] = -unit
                grad[k, 3 + 2 * k : 5 + 2 * k] = unit
        rho[3] = s[0] - s[1] + self.half_width
        rho[4] = s[1] - s[0] + self.half_width
        grad[3, 0], grad[3, 1] = 1.0, -1.0
        grad[4, 0], grad[4, 1] = -1.0, 1.0
        return rho, grad

    def dynamics(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """f (13,) and g (13, 2) of the unicycle reference point (Eq. 6A2)."""
        f = np.zeros(s.shape[0])
        g = np.zeros((s.shape[0], 2))
        sin, cos = np.sin(s[2]), np.cos(s[2])
        g[0] = (cos, -self.eps * sin)
        g[1] = (sin, self.eps * cos)
        g[2, 1] = 1.0
        return f, g


class Structure:
    """The automaton's structure read once as text: the progress-preserving safe set's CNF
    (the shield's default), the ranks and the edges per state."""

    def __init__(self, automaton: Any) -> None:
        atoms = automaton.atoms
        self.cnf = {
            q: [
                [(atoms.index(a), pos) for a, pos in map(literal, clause)]
                for clause in automaton.avoid_cnf(q)
            ]
            for q in range(automaton.num_states)
        }
        if automaton.trap is not None:
            # The trap keeps what every state with an edge into it kept: the intersection of
            # their negated trap guards (as sets of literals, whatever their order).
            into = [
                {frozenset(clause) for clause in automaton.trap_cnf(q)}
                for q in range(automaton.num_states)
                if q != automaton.trap and automaton.trap_cnf(q)
            ]
            kept = set.intersection(*into) if into else set()
            self.cnf[automaton.trap] = [
                [(atoms.index(a), pos) for a, pos in map(literal, sorted(clause))]
                for clause in sorted(kept, key=sorted)
            ]
        self.ranks = automaton.ranks
        self.progress: dict[int, list[list[Cube]]] = {q: [] for q in range(automaton.num_states)}
        self.edges: dict[int, list[tuple[int, list[Cube]]]] = {
            q: [] for q in range(automaton.num_states)
        }
        for src, dst, guard in automaton.edges():
            cubes = parse_guard(guard, atoms)
            self.edges[src].append((dst, cubes))
            if src != dst and dst != automaton.trap:
                self.progress[src].append(cubes)

    def next_state(self, q: int, rho: np.ndarray) -> int:
        """The edge whose guard holds (an atom holds iff its robustness is > 0)."""
        holds = rho > 0
        for dst, cubes in self.edges[q]:
            if any(all(holds[a] == pos for a, pos in cube) for cube in cubes):
                return dst
        raise AssertionError(f"no edge of {q} holds")

    def safe_set(self, q: int, rho: np.ndarray) -> list[tuple[int, bool]]:
        """Eq. 5C1: per clause the literal with the largest robustness (first on ties), each
        literal once."""
        kept: list[tuple[int, bool]] = []
        for clause in self.cnf[q]:
            values = [rho[a] if pos else -rho[a] for a, pos in clause]
            chosen = clause[int(np.argmax(values))]
            if chosen not in kept:
                kept.append(chosen)
        return kept

    def goal(self, q: int, s: np.ndarray, rho: np.ndarray, task: Task) -> np.ndarray | None:
        """Eq. 5B1, rank-aware: over edges to states strictly closer to acceptance, the cubes
        with a goal ball in order of robustness (first on ties); the first whose regions meet
        at s gives the deepest point of its positive regions (cvxpy)."""
        rank = self.ranks[q]
        if rank is None:
            return None
        candidates: list[tuple[float, Cube]] = []
        for dst, cubes in self.edges[q]:
            if dst == q or self.ranks[dst] is None or self.ranks[dst] >= rank:
                continue
            for cube in cubes:
                if any(pos and a < 3 for a, pos in cube):
                    value = min(rho[a] if pos else -rho[a] for a, pos in cube)
                    candidates.append((value, cube))
        for _, cube in sorted(candidates, key=lambda c: -c[0]):
            point = deepest_point(cube, s, task)
            if point is not None:
                return point
        return None


def deepest_point(cube: Cube, s: np.ndarray, task: Task) -> np.ndarray | None:
    """argmax_x min over the cube's positive regions (goal balls, channel half-spaces) of their
    robustness at x; None when it is <= 1e-7 (they do not meet)."""
    balls = [s[3 + 2 * a : 5 + 2 * a] for a, pos in cube if pos and a < 3]
    walls = [(np.array([1.0, -1.0]) * (1 if a == 3 else -1)) for a, pos in cube if pos and a >= 3]
    r, b = task.goal_radius, task.half_width
    if len(balls) == 1 and all(w @ balls[0] + b >= r for w in walls):
        return np.array(balls[0], dtype=float)
    import cvxpy as cp

    x, t = cp.Variable(2), cp.Variable()
    rows = [r - cp.norm(x - c) >= t for c in balls] + [w @ x + b >= t for w in walls]
    cp.Problem(cp.Maximize(t), rows).solve()
    if t.value is None or t.value <= 1e-7:
        return None
    return np.asarray(x.value, dtype=float)


@dataclass
class Rows:
    """The QP data of one step: barrier rows, CLF row, and what they were built from."""

    lg: np.ndarray  # (nb, m): Lg h_i
    rhs: np.ndarray  # (nb,)
    clf_lg: np.ndarray  # (m,) (zeros without a goal)
    clf_rhs: float  # row right-hand side including delta_0
    delta_0: float
    has_goal: bool


@dataclass
class Params:
    """Shield parameters, as in tlshield.Shield."""

    alpha: float = 2.0
    c3: float = 1.0
    k: float = 1e4
    cbf: tuple[float, float] = (-6.0, 6.0)
    clf: tuple[float, float] = (-0.5, 0.5)
    slack_penalty: float = 1e6
    margin: float = 1e-6


def build_rows(
    task: Task, structure: Structure, params: Params, s: np.ndarray, q: int, a_rl: np.ndarray
) -> Rows:
    """Predicates, safe set, goal and the constraint rows in numpy."""
    rho, grad = task.atoms(s)
    f, g = task.dynamics(s)
    lg_rows, rhs = [], []
    for atom, positive in structure.safe_set(q, rho):
        sign = 1.0 if positive else -1.0
        h, dh = sign * rho[atom], sign * grad[atom]
        lg = dh @ g
        lg_rows.append(lg)
        rhs.append(dh @ f + lg @ a_rl + params.alpha * (h - params.margin))
    goal = structure.goal(q, s, rho, task)
    clf_lg = np.zeros(2)
    clf_rhs = delta_0 = 0.0
    if goal is not None:
        e = s[:2] - goal
        v = float(e @ e)
        dv = np.zeros(s.shape[0])
        dv[:2] = 2.0 * e
        clf_lg = dv @ g
        row_rhs = -(dv @ f + clf_lg @ a_rl + params.c3 * v)
        lo, hi = params.clf
        best = float(np.minimum(clf_lg * lo, clf_lg * hi).sum())
        delta_0 = max(best - row_rhs, 0.0)
        clf_rhs = row_rhs + delta_0
    return Rows(
        lg=np.array(lg_rows).reshape(-1, 2),
        rhs=np.array(rhs),
        clf_lg=clf_lg,
        clf_rhs=clf_rhs,
        delta_0=delta_0,
        has_goal=goal is not None,
    )


MAX_BARRIERS = 4


class CvxpyShield:
    """The QP as a cvxpy problem with Parameters, built once (DPP), solved by CLARABEL.
    Barrier rows are padded to MAX_BARRIERS with always-true rows."""

    def __init__(self, params: Params, relaxed: bool = False) -> None:
        import cvxpy as cp

        self.params = params
        self.a_cbf = cp.Variable(2)
        self.a_clf = cp.Variable(2)
        self.d = cp.Variable(nonneg=True)
        self.lg = cp.Parameter((MAX_BARRIERS, 2))
        self.rhs = cp.Parameter(MAX_BARRIERS)
        self.clf_lg = cp.Parameter(2)
        self.clf_rhs = cp.Parameter()
        # Without a goal the shield has no a_clf: its box shrinks to {0}.
        self.clf_lo = cp.Parameter(2)
        self.clf_hi = cp.Parameter(2)
        barrier = -self.lg @ (self.a_cbf + self.a_clf)
        cost = cp.sum_squares(self.a_cbf) + cp.sum_squares(self.a_clf) + params.k * self.d
        self.sigma = cp.Variable(MAX_BARRIERS, nonneg=True) if relaxed else None
        if self.sigma is not None:
            barrier = barrier - self.sigma
            cost = cost + params.slack_penalty * cp.sum(self.sigma)
        lo, hi = params.cbf
        constraints = [
            barrier <= self.rhs,
            self.clf_lg @ self.a_clf - self.d <= self.clf_rhs,
            self.a_cbf >= lo,
            self.a_cbf <= hi,
            self.a_clf >= self.clf_lo,
            self.a_clf <= self.clf_hi,
        ]
        self.problem = cp.Problem(cp.Minimize(cost), constraints)
        self.settings = {
            "tol_gap_abs": 1e-10,
            "tol_gap_rel": 1e-10,
            "tol_feas": 1e-10,
            "tol_ktratio": 1e-8,
        }

    def solve(
        self, rows: Rows, fresh: bool = False
    ) -> tuple[np.ndarray, np.ndarray, float, str] | None:
        """(a_cbf, a_clf, delta, cvxpy status), or None when not solved (by a fresh problem)."""
        nb = rows.lg.shape[0]
        lg = np.zeros((MAX_BARRIERS, 2))
        rhs = np.full(MAX_BARRIERS, 1.0)
        lg[:nb], rhs[:nb] = rows.lg, rows.rhs
        self.lg.value, self.rhs.value = lg, rhs
        self.clf_lg.value, self.clf_rhs.value = rows.clf_lg, rows.clf_rhs
        clo, chi = self.params.clf if rows.has_goal else (0.0, 0.0)
        self.clf_lo.value, self.clf_hi.value = np.full(2, clo), np.full(2, chi)
        self.problem.solve(solver="CLARABEL", **self.settings)
        if self.problem.status not in ("optimal", "optimal_inaccurate"):
            if fresh:
                return None
            # After many solves of the same parametrised problem, Clarabel via cvxpy has
            # (rarely) reported a borderline instance infeasible that a freshly built problem
            # solves to optimality: infeasibility is only concluded by a fresh problem.
            return CvxpyShield(self.params, relaxed=self.sigma is not None).solve(rows, fresh=True)
        d = float(self.d.value) if rows.has_goal else 0.0
        return (
            np.asarray(self.a_cbf.value),
            np.asarray(self.a_clf.value),
            rows.delta_0 + max(d, 0.0),
            self.problem.status,
        )


class ClarabelShield:
    """The same QP through clarabel's Python API: P, A's pattern and the cones set up once,
    then per step only q, A's values and b updated (a dense A keeps the pattern fixed)."""

    def __init__(self, params: Params) -> None:
        import clarabel

        self.clarabel = clarabel
        self.params = params
        n = 5  # a_cbf (2), a_clf (2), d
        self.rows = MAX_BARRIERS + 2 + 8
        self.P = sp.csc_matrix(np.diag([2.0, 2.0, 2.0, 2.0, 0.0]))
        self.q = np.array([0.0, 0.0, 0.0, 0.0, params.k])
        self.A = np.zeros((self.rows, n))
        self.b = np.zeros(self.rows)
        lo, hi = params.cbf
        clo, chi = params.clf
        r = MAX_BARRIERS
        self.A[r + 1, 4] = -1.0  # d >= 0
        for j in range(4):
            upper, lower = (hi, lo) if j < 2 else (chi, clo)
            self.A[r + 2 + 2 * j, j], self.b[r + 2 + 2 * j] = 1.0, upper
            self.A[r + 3 + 2 * j, j], self.b[r + 3 + 2 * j] = -1.0, -lower
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        settings.presolve_enable = False
        settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = 1e-10
        settings.tol_ktratio = 1e-8
        self.settings = settings
        self.cones = [clarabel.NonnegativeConeT(self.rows)]
        self.solver = clarabel.DefaultSolver(
            self.P, self.q, self._csc(), self.b, self.cones, settings
        )

    def _csc(self) -> sp.csc_matrix:
        # Every entry structural (a tiny epsilon would change the numbers; build the pattern
        # explicitly instead).
        rows, cols = self.A.shape
        indptr = np.arange(0, rows * cols + 1, rows)
        indices = np.tile(np.arange(rows), cols)
        return sp.csc_matrix((self.A.T.ravel(), indices, indptr), shape=(rows, cols))

    def solve(self, rows: Rows) -> tuple[np.ndarray, np.ndarray, float, str] | None:
        nb = rows.lg.shape[0]
        r = MAX_BARRIERS
        self.A[:r, :] = 0.0
        self.b[:r] = 1.0
        self.A[:nb, 0:2] = -rows.lg
        self.A[:nb, 2:4] = -rows.lg
        self.b[:nb] = rows.rhs
        self.A[r, 2:4] = rows.clf_lg
        self.A[r, 4] = -1.0
        self.b[r] = rows.clf_rhs
        clo, chi = self.params.clf if rows.has_goal else (0.0, 0.0)
        self.b[r + 6], self.b[r + 7] = chi, -clo
        self.b[r + 8], self.b[r + 9] = chi, -clo
        # A's values in CSC (column-major) order; the pattern is dense and fixed.
        self.solver.update(A=self.A.T.ravel(), b=self.b)
        sol = self.solver.solve()
        if str(sol.status) not in ("Solved", "AlmostSolved"):
            return None
        x = np.asarray(sol.x)
        d = float(x[4]) if rows.has_goal else 0.0
        return x[0:2], x[2:4], rows.delta_0 + max(d, 0.0), str(sol.status)


def assert_matches(
    got: Any,
    rows: Rows,
    a_rl: np.ndarray,
    solvers: tuple[CvxpyShield, CvxpyShield],
    tol: float,
) -> None:
    """The shield's result ``got`` equals cvxpy's solve of ``rows`` within ``tol``: status
    solved when cvxpy solves the QP as posed, relaxed (and equal to the relaxed solve) when
    only the relaxed problem is feasible."""
    from tlshield import Status

    cvx, cvx_relaxed = solvers
    want = cvx.solve(rows)
    if want is None:
        assert got.status == Status.RELAXED, got
        want = cvx_relaxed.solve(rows)
        assert want is not None
    else:
        assert got.status == Status.SOLVED, (got, want)
    a_cbf, a_clf, delta, _ = want
    np.testing.assert_allclose(got.action, a_rl + a_cbf + a_clf, atol=tol, rtol=0)
    assert abs(got.delta - delta) <= tol * max(1.0, delta)
    assert all(np.isfinite(got.action))
