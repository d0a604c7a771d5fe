"""The shield's outcome codes, one encoding for ``Shield.filter`` and ``Shield.filter_batch``:
``FilterResult.status`` is a :class:`Status`, ``FilterBatch.status`` an array of its values
(compare with ``batch.status == Status.RELAXED``). Both are :class:`enum.IntEnum`, so they
serialise as plain integers. ``Shield.vjp_batch``'s per-row flags are :class:`GradFlag` bits.
Every value is the core's own (``STATUS_CODES``, ``SOLVER_CODES`` and the ``GRAD_*`` bits),
so the two cannot drift apart."""

from enum import IntEnum, IntFlag

from tlshield._core import (
    GRAD_DEGENERATE,
    GRAD_FAILED,
    GRAD_RELAXED,
    GRAD_ROUTED,
    GRAD_SINGULAR,
    SOLVER_CODES,
    STATUS_CODES,
)

__all__ = ["GradFlag", "Solver", "Status"]


class Status(IntEnum):
    """How the QP of one shield step ended."""

    #: Solved as posed.
    SOLVED = STATUS_CODES["solved"]
    #: The barriers could not all hold: solved with slack on the barrier rows (the largest is
    #: ``FilterResult.slack``).
    RELAXED = STATUS_CODES["relaxed"]
    #: No solution: zero corrections, the RL action unchanged.
    FAILED = STATUS_CODES["failed"]
    #: The solver called the problem solved, but its answer broke a constraint by more than
    #: the shield's residual tolerance (1e-7 of the row's scale); the action is the relaxed
    #: problem's answer, which passed the same check.
    INACCURATE = STATUS_CODES["inaccurate"]

    def __str__(self) -> str:
        return self.name.lower()


class Solver(IntEnum):
    """Which solver answered one shield step."""

    #: No QP (nothing to correct, or failed).
    NONE = SOLVER_CODES["none"]
    #: The dense active-set solver.
    ACTIVE_SET = SOLVER_CODES["active_set"]
    #: Clarabel (interior point).
    CLARABEL = SOLVER_CODES["clarabel"]

    def __str__(self) -> str:
        return self.name.lower()


class GradFlag(IntFlag):
    """What one row of ``Shield.vjp_batch`` differentiated (bits; 0 is an exact two-sided
    gradient of a step solved as posed). Test with ``flags & GradFlag.DEGENERATE``."""

    #: The step was relaxed: the gradient is the relaxed QP's (slacks on the barrier rows).
    RELAXED = GRAD_RELAXED
    #: The step failed and returned ``a_rl``: the gradient is the identity.
    FAILED = GRAD_FAILED
    #: The active set changes at this point (a tight row with a zero multiplier, or tight rows
    #: that depend on each other): the one-sided derivative of the piece on which every tight
    #: row stays tight.
    DEGENERATE = GRAD_DEGENERATE
    #: The KKT system on the active rows was singular: only the identity part is returned.
    SINGULAR = GRAD_SINGULAR
    #: Routing changed the CLF row (a target around an obstacle, or progress into one
    #: uncredited): ``dL/da_rl`` is exact; ``dL/ds`` holds the target fixed.
    ROUTED = GRAD_ROUTED
