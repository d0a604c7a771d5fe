"""tlshield: temporal-logic guided safe reinforcement learning.

Write a task as an scTLTL formula over state predicates; tlshield computes its robustness
(and, in later modules, the automaton, reward and CLF-CBF shield) in a Rust core.

>>> import numpy as np, tlshield
>>> spec = tlshield.Spec("F low", {"low": tlshield.Halfspace([-1.0], 4.0)})
>>> spec.robustness(np.array([[6.0], [5.0], [4.5], [3.5]]))
0.5
"""

from tlshield._core import (
    Automaton,
    Ball,
    Halfspace,
    Spec,
    SpecError,
    __version__,
    formula_atoms,
)

__all__ = ["Automaton", "Ball", "Halfspace", "Spec", "SpecError", "__version__", "formula_atoms"]
