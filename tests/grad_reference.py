"""A differentiable reference for the shield's gradients, independent of the core's: the rows of
Eq. 5D2 for the case study written in torch (barrier gradients by torch's own autograd, so the
state derivatives of ``Lg h`` come from a second autograd pass, not from the core's hand-written
chain rule), and the QP solved and differentiated by cvxpylayers (diffcp, Clarabel).

The discrete choices of a step (the FSA state, which literal each safe-set clause keeps, which
goal the CLF tracks) come from :mod:`tests.shield_reference` at the unperturbed state, as they
are locally constant. Steps whose CLF goal is not a single goal ball's centre (the deepest point
of several regions) are not covered: :func:`rows` returns None for them.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from tests.shield_reference import MAX_BARRIERS, CvxpyShield, Params, Structure, Task

#: The reference solve: Clarabel through diffcp at tight tolerances, and diffcp's dense
#: derivative (its default, LSQR, is iterative and less exact).
SOLVER_ARGS = {
    "solve_method": "Clarabel",
    "mode": "dense",
    "tol_gap_abs": 1e-12,
    "tol_gap_rel": 1e-12,
    "tol_feas": 1e-12,
    "tol_ktratio": 1e-10,
}


def _atom(task: Task, s: torch.Tensor, k: int) -> torch.Tensor:
    """Robustness of atom k (g1, g2, g3, c1, c2) at s, in torch."""
    if k < 3:
        return task.goal_radius - torch.linalg.norm(s[:2] - s[3 + 2 * k : 5 + 2 * k])
    sign = 1.0 if k == 3 else -1.0
    return sign * (s[0] - s[1]) + task.half_width


def _g(task: Task, s: torch.Tensor) -> torch.Tensor:
    """g(s) (n, 2) of the unicycle reference point (Eq. 6A2); f = 0."""
    sin, cos = torch.sin(s[2]), torch.cos(s[2])
    zero, one = torch.zeros_like(sin), torch.ones_like(sin)
    rows = [
        torch.stack([cos, -task.eps * sin]),
        torch.stack([sin, task.eps * cos]),
        torch.stack([zero, one]),
    ]
    rows += [torch.stack([zero, zero])] * (s.shape[0] - 3)
    return torch.stack(rows)


def rows(
    task: Task,
    structure: Structure,
    params: Params,
    s: torch.Tensor,
    q: int,
    a_rl: torch.Tensor,
) -> tuple[torch.Tensor, ...] | None:
    """The QP's parameters ``(lg, rhs, clf_lg, clf_rhs, clf_lo, clf_hi)`` as differentiable
    functions of ``s`` and ``a_rl`` (padded as :class:`CvxpyShield` expects), or None when the
    goal is not a ball's centre."""
    s_np = s.detach().numpy()
    rho, _ = task.atoms(s_np)
    g = _g(task, s)
    lgs, rhs = [], []
    for atom, positive in structure.safe_set(q, rho):
        sign = 1.0 if positive else -1.0
        h = sign * _atom(task, s, atom)
        (grad,) = torch.autograd.grad(h, s, create_graph=True)
        lg = grad @ g
        lgs.append(lg)
        rhs.append(lg @ a_rl + params.alpha * (h - params.margin))
    pad = MAX_BARRIERS - len(lgs)
    lg_t = torch.stack(lgs + [torch.zeros(2, dtype=s.dtype)] * pad)
    rhs_t = torch.stack(rhs + [torch.ones((), dtype=s.dtype)] * pad)
    goal = structure.goal(q, s_np, rho, task)
    lo, hi = params.clf
    if goal is None:
        zeros = torch.zeros(2, dtype=s.dtype)
        return lg_t, rhs_t, zeros, torch.zeros((), dtype=s.dtype), zeros, zeros
    ball = [k for k in range(3) if np.array_equal(goal, s_np[3 + 2 * k : 5 + 2 * k])]
    if not ball:
        return None
    e = s[:2] - s[3 + 2 * ball[0] : 5 + 2 * ball[0]]
    clf_lg = 2.0 * e @ g[:2]
    row_rhs = -(clf_lg @ a_rl + params.c3 * (e @ e))
    best = torch.minimum(clf_lg * lo, clf_lg * hi).sum()
    clf_rhs = row_rhs + torch.relu(best - row_rhs)
    box = torch.ones(2, dtype=s.dtype)
    return lg_t, rhs_t, clf_lg, clf_rhs, lo * box, hi * box


class ReferenceLayer:
    """``safe_action(s, q, a_rl)`` through cvxpylayers; backpropagates to ``s`` and ``a_rl``."""

    def __init__(self, params: Params, structure: Structure, task: Task | None = None) -> None:
        from cvxpylayers.torch import CvxpyLayer

        self.params, self.structure, self.task = params, structure, task or Task()
        qp = CvxpyShield(params)
        self.layer = CvxpyLayer(
            qp.problem,
            parameters=[qp.lg, qp.rhs, qp.clf_lg, qp.clf_rhs, qp.clf_lo, qp.clf_hi],
            variables=[qp.a_cbf, qp.a_clf, qp.d],
        )

    def safe_action(self, s: torch.Tensor, q: int, a_rl: torch.Tensor) -> torch.Tensor | None:
        data = rows(self.task, self.structure, self.params, s, q, a_rl)
        if data is None:
            return None
        a_cbf, a_clf, _ = self.layer(*data, solver_args=dict(SOLVER_ARGS))
        return a_rl + a_cbf + a_clf

    def gradients(
        self, s: np.ndarray, q: int, a_rl: np.ndarray, v: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """``(dL/da_rl, dL/ds, safe action)`` of ``L = v . safe_action``, or None (goal not a
        ball)."""
        s_t = torch.tensor(s, dtype=torch.float64, requires_grad=True)
        a_t = torch.tensor(a_rl, dtype=torch.float64, requires_grad=True)
        out = self.safe_action(s_t, q, a_t)
        if out is None:
            return None
        loss: Any = out @ torch.tensor(v, dtype=torch.float64)
        ga, gs = torch.autograd.grad(loss, (a_t, s_t))
        return ga.numpy(), gs.numpy(), out.detach().numpy()
