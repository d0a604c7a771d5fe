"""Copies of environments are independent. A bundled env keeps its state (the world, the task
monitor) in core objects, so Python's default shallow ``copy.copy`` would hand the copy the
same world: stepping one would step both. :class:`IndependentCopies` makes ``copy.copy`` a
full copy, as ``copy.deepcopy`` and ``pickle`` are (every core object pickles as data)."""

from __future__ import annotations

import copy
from typing import Any


class IndependentCopies:
    """``copy.copy(x)`` is ``copy.deepcopy(x)``: the copy continues exactly as the original
    would, through the same random stream, without touching it."""

    def __copy__(self) -> Any:
        return copy.deepcopy(self)
