"""What training and evaluation count as a violation and a collision, read from the task
itself so that a user's environment needs no extra ``info`` keys.

The keys read here are declared in :class:`tlshield.step_info.StepInfo`. A step's
**violation** is the environment's own ``info["violation"]`` when it reports one (its
definition of unsafe); otherwise it is measured: a user barrier below zero at the new state
(``info["barriers"]``, which :class:`tlshield.wrappers.Shielded` writes) or an entry into the
automaton's trap (``info["trap"]``, the formula's safety broken). A **collision** is only ever
the environment's ``info["collision"]``: nothing else says what touching means, so without the
key it is not measured. A count that could not be measured is ``None`` ("not measured"),
never 0.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from tlshield.step_info import StepInfo

#: How results print a count that could not be measured.
NOT_MEASURED = "not measured"


def step_violation(info: StepInfo | Mapping[str, Any], was_trapped: bool) -> bool | None:
    """Whether this step violated safety (see the module's docs); ``None`` when nothing in
    ``info`` tells. ``was_trapped``: the episode was in the trap before this step."""
    if "violation" in info:
        return bool(info["violation"])
    known, violated = False, False
    barriers = info.get("barriers")
    if barriers:
        known, violated = True, min(barriers.values()) < 0.0
    if "trap" in info:
        known, violated = True, violated or (bool(info["trap"]) and not was_trapped)
    return violated if known else None


def collision(info: StepInfo | Mapping[str, Any]) -> bool | None:
    """The environment's own collision flag; ``None`` when it reports none."""
    return bool(info["collision"]) if "collision" in info else None


def total(counts: list[int | None]) -> int | None:
    """The sum of per-step or per-trial counts, ``None`` when none was measured."""
    known = [c for c in counts if c is not None]
    return sum(known) if known else None


def shown(count: int | None) -> str:
    """A count as results print it."""
    return NOT_MEASURED if count is None else str(count)
