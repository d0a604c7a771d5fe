"""tlshield: temporal-logic guided safe reinforcement learning.

Write a task as an scTLTL formula over state predicates; tlshield computes its robustness,
its automaton (FSA-augmented reward, CBF safe sets, CLF goals) and the CLF-CBF shield that
corrects an RL agent's actions, in a Rust core.

>>> import numpy as np, tlshield
>>> spec = tlshield.Spec("F low", {"low": tlshield.Halfspace([-1.0], 4.0)})
>>> spec.robustness(np.array([[6.0], [5.0], [4.5], [3.5]]))
0.5
"""

from tlshield import envs
from tlshield._core import (
    AccelerationUnicycle,
    Automaton,
    AutomatonError,
    Avoid,
    Ball,
    ControlAffine,
    DoubleIntegrator,
    FilterBatch,
    FilterResult,
    Halfspace,
    Inside,
    Intersection,
    KinematicBicycle,
    Monitor,
    MonitorBatch,
    ProgressReward,
    Shield,
    ShieldError,
    SingleIntegrator,
    Spec,
    SpecError,
    TaskBatch,
    TaskStep,
    ThrustTurn,
    Unicycle,
    Union,
    __version__,
    formula_atoms,
)
from tlshield.codes import GradFlag, Solver, Status

__all__ = [
    "AccelerationUnicycle",
    "Automaton",
    "AutomatonError",
    "Avoid",
    "Ball",
    "ControlAffine",
    "DoubleIntegrator",
    "FilterBatch",
    "FilterResult",
    "GradFlag",
    "Halfspace",
    "Inside",
    "Intersection",
    "KinematicBicycle",
    "Monitor",
    "MonitorBatch",
    "ProgressReward",
    "Shield",
    "ShieldError",
    "SingleIntegrator",
    "Solver",
    "Spec",
    "SpecError",
    "Status",
    "TaskBatch",
    "TaskStep",
    "ThrustTurn",
    "Unicycle",
    "Union",
    "__version__",
    "envs",
    "formula_atoms",
]
