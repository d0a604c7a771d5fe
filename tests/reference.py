"""A small pure-Python reference for scTLTL robustness, independent of the Rust core.

Formulas are nested tuples: ("atom", name), ("true",), ("false",), ("not", a), ("and", a, b),
("or", a, b), ("implies", a, b), ("until", a, b), ("F", a), ("X", a). Semantics are the direct
definitions (closed window), evaluated by brute force.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

import numpy as np

Formula = tuple


def robustness(
    f: Formula, traj: np.ndarray, preds: Mapping[str, Callable[[np.ndarray], float]], t: int = 0
) -> float:
    """rho(traj, f, t) by the definitions."""
    last = len(traj) - 1
    op = f[0]
    if op == "true":
        return math.inf
    if op == "false":
        return -math.inf
    if op == "atom":
        return preds[f[1]](traj[t])
    if op == "not":
        return -robustness(f[1], traj, preds, t)
    if op == "and":
        return min(robustness(f[1], traj, preds, t), robustness(f[2], traj, preds, t))
    if op == "or":
        return max(robustness(f[1], traj, preds, t), robustness(f[2], traj, preds, t))
    if op == "implies":
        return max(-robustness(f[1], traj, preds, t), robustness(f[2], traj, preds, t))
    if op == "F":
        return max(robustness(f[1], traj, preds, u) for u in range(t, last + 1))
    if op == "X":
        return robustness(f[1], traj, preds, t + 1) if t < last else -math.inf
    if op == "until":
        best = -math.inf
        for u in range(t, last + 1):
            before = min((robustness(f[1], traj, preds, v) for v in range(t, u)), default=math.inf)
            best = max(best, min(robustness(f[2], traj, preds, u), before))
        return best
    raise ValueError(f"unknown operator {op!r}")


def satisfied(
    f: Formula, traj: np.ndarray, preds: Mapping[str, Callable[[np.ndarray], float]], t: int = 0
) -> bool:
    """Boolean semantics by the definitions (an atom holds iff its robustness is > 0)."""
    last = len(traj) - 1
    op = f[0]
    if op == "true":
        return True
    if op == "false":
        return False
    if op == "atom":
        return preds[f[1]](traj[t]) > 0
    if op == "not":
        return not satisfied(f[1], traj, preds, t)
    if op == "and":
        return satisfied(f[1], traj, preds, t) and satisfied(f[2], traj, preds, t)
    if op == "or":
        return satisfied(f[1], traj, preds, t) or satisfied(f[2], traj, preds, t)
    if op == "implies":
        return (not satisfied(f[1], traj, preds, t)) or satisfied(f[2], traj, preds, t)
    if op == "F":
        return any(satisfied(f[1], traj, preds, u) for u in range(t, last + 1))
    if op == "X":
        return t < last and satisfied(f[1], traj, preds, t + 1)
    if op == "until":
        return any(
            satisfied(f[2], traj, preds, u)
            and all(satisfied(f[1], traj, preds, v) for v in range(t, u))
            for u in range(t, last + 1)
        )
    raise ValueError(f"unknown operator {op!r}")


def to_text(f: Formula) -> str:
    """Fully parenthesised formula text in the tlshield grammar."""
    op = f[0]
    if op == "atom":
        return f[1]
    if op in ("true", "false"):
        return op
    if op == "not":
        return f"!({to_text(f[1])})"
    if op in ("F", "X"):
        return f"{op} ({to_text(f[1])})"
    symbol = {"and": "&", "or": "|", "implies": "->", "until": "U"}[op]
    return f"({to_text(f[1])}) {symbol} ({to_text(f[2])})"


def halfspace(w: np.ndarray, b: float) -> Callable[[np.ndarray], float]:
    """Reference half-space predicate."""
    return lambda s: float(np.dot(w, s) + b)


def ball(pos: list[int], radius: float, center: np.ndarray) -> Callable[[np.ndarray], float]:
    """Reference ball predicate with a fixed centre."""
    return lambda s: float(
        radius - math.sqrt(sum((s[p] - c) ** 2 for p, c in zip(pos, center, strict=True)))
    )
