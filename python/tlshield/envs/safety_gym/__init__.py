"""Safety-Gymnasium's navigation tasks (PKU-Alignment), adapted to tlshield's stack and shielded.

**The adapter** (:mod:`~tlshield.envs.safety_gym.adapter`). safety-gymnasium 1.0.0 as published
does not import with gymnasium 1.x and Python 3.11: its package ``__init__`` imports
``gymnasium.wrappers.compatibility`` (removed in gymnasium 1.0), and its colours are numpy
arrays used as dataclass defaults (refused since Python 3.11: unhashable), and its Car robot
reads a joint by the id a sensor's view gives, a one-element numpy array, which MuJoCo 2.3.7's
``MjModel.jnt`` refuses under numpy 2. :func:`load_builder` checks the installed versions
(:data:`VERSIONS`), makes the package importable without running its ``__init__`` (a module
shell whose ``__path__`` is the package's folder), makes the colour arrays hashable (a view
with identity hashing; the values are untouched), lets ``MjModel.jnt`` take a one-element
integer array as the integer it holds (every other argument goes through as it is), and
returns its ``Builder``, the env class every Safety-Gymnasium task is made from. Nothing else
is patched; what stays patched after it returns, and what it undoes when it fails, is in its
docstring. ``make safety-gym`` installs the stack (docs/guides/safety-gym.md says what and
why).

**The shielded envs** ``tlshield/SafetyPointGoal1-v0``, ``tlshield/SafetyPointGoal2-v0`` and
``tlshield/SafetyCarGoal1-v0`` (:class:`SafetyGoalEnv`, :mod:`~tlshield.envs.safety_gym.env`)
keep Safety-Gymnasium's observation, action, reward and cost (``info["cost"]``); the shield
reads the **privileged true state** (the agent's pose and velocity from MuJoCo, the goal,
hazards and vases), which the policy never sees:

* the robot (:mod:`~tlshield.envs.safety_gym.robots`): :class:`tlshield.ThrustTurn`,
  identified from MuJoCo (:data:`POINT`), with the measured one-step error as the shield's
  ``disturbance`` bounds; the Car a :class:`tlshield.ControlAffine` model identified the same
  way (:data:`CAR`);
* the task (:mod:`~tlshield.envs.safety_gym.task`): ``(!h1 & ... & !hN & !v1 & ...) U goal``,
  hazards (and Goal2's vases) in the formula: its safe set keeps them out, and its CLF drives
  to the goal. When the goal is met Safety-Gymnasium places a new one and the task starts
  again.

**The lidar** (:mod:`~tlshield.envs.safety_gym.lidar`): what Safety-Gymnasium's pseudo-lidar
bins say about the objects around the robot, read without MuJoCo's positions (per bin, the
distance no centre is nearer than; a lone object's exact position; the discs a barrier can
hold on), and the lidar itself, to measure against (``scripts/lidar_estimate.py``).

Every name of the adapter, env, robots and task modules is importable from this package as
from its module; the lidar's are read from their module (``from tlshield.envs.safety_gym
import lidar``). The lidar hazard attacker the scripts use is ``hazard_attacker`` in
``scripts/safety_gym_attack.py``.
"""

from __future__ import annotations

from tlshield._removed import refuse
from tlshield.envs.safety_gym.adapter import (
    BUILDER_TASKS,
    INSTALL,
    TASKS,
    VERSIONS,
    MissingStack,
    installed,
    load_builder,
    make_builder,
)
from tlshield.envs.safety_gym.env import ACTIONS, SafetyGoalEnv, make_safety_goal
from tlshield.envs.safety_gym.robots import (
    CAR,
    POINT,
    ROBOTS,
    CarModel,
    PointModel,
    Robot,
    robot_of,
)
from tlshield.envs.safety_gym.task import SafetyGoalParams, goal_spec

#: Names that left this package, with where they went.
#: Names removed in 0.4, refused with a message naming what replaced them.
__getattr__ = refuse(
    __name__,
    {
        "hazard_attacker": "scripts/safety_gym_attack.py's hazard_attacker (a scripted policy "
        "of the scripts, not part of the library): import it from there"
    },
)


__all__ = [
    "ACTIONS",
    "BUILDER_TASKS",
    "CAR",
    "INSTALL",
    "POINT",
    "ROBOTS",
    "TASKS",
    "VERSIONS",
    "CarModel",
    "MissingStack",
    "PointModel",
    "Robot",
    "SafetyGoalEnv",
    "SafetyGoalParams",
    "goal_spec",
    "installed",
    "load_builder",
    "make_builder",
    "make_safety_goal",
    "robot_of",
]
