"""What a shielded step returns in ``info``, declared once: :class:`StepInfo` (every key a
bundled env, a wrapper or a vector env writes, and what it means) and :class:`ShieldInfo` (the
``info["shield"]`` entry of a step a shield filtered), as EnvPool declares its state spec.
:mod:`tlshield.lab.measures`, training's metrics and evaluation read these keys and no others.

:func:`shield_info` builds ``info["shield"]`` for every env that steps in Python
(:class:`tlshield.wrappers.Shielded`, Safety-Gymnasium's envs); the core-stepped envs
(Channel-v0, PointMass-v0) build the same keys in the core. ``info["shield"]`` is there when a
shield filtered the step, and only then.

:class:`ShieldedStep` is the step of an env written in Python around a task monitor: filter the
RL action (reading the monitor), apply it, advance the monitor, build ``info``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypedDict

import numpy as np
from numpy.typing import NDArray

from tlshield._core import FilterResult, Monitor, Shield, TaskStep
from tlshield.codes import Solver, Status

__all__ = ["ShieldInfo", "ShieldedStep", "StepInfo", "shield_info"]


class ShieldInfo(TypedDict, total=False):
    """``info["shield"]``: what the shield did to this step's action. A vector env's batch
    entry has the first seven keys (a batch does not return the goal or the barriers)."""

    #: The RL action, in the shield's units.
    a_rl: NDArray[np.float64]
    #: The CBF's correction (``a = a_rl + a_cbf + a_clf``).
    a_cbf: NDArray[np.float64]
    #: The CLF's part.
    a_clf: NDArray[np.float64]
    #: The CLF's relaxation (Eq. 5D2's ``delta``).
    delta: float
    #: How the QP ended (:class:`tlshield.Status`).
    status: Status
    #: The largest barrier slack (> 0 only when the QP was relaxed).
    slack: float
    #: Which solver answered (:class:`tlshield.Solver`).
    solver: Solver
    #: The barrier that gave way, ``(name, slack)``, or None.
    gave_way: tuple[str, float] | None
    #: The CLF goal (or None without one).
    goal: NDArray[np.float64] | None
    #: The goal cannot be reached from the state, as far as the routing guidance can tell
    #: (``FilterResult.goal_unreachable``): the shield parks the robot safely short of it.
    goal_unreachable: bool
    #: The enforced barriers, ``{name: h(s)}`` at the state the shield read.
    barriers: dict[str, float]


class StepInfo(TypedDict, total=False):
    """``info`` of a step (and of a reset, which has the task's and the measures' keys). Every
    key is optional: an env writes those it can tell, and the lab counts what is missing as
    not measured, never as safe (:mod:`tlshield.lab.measures`)."""

    #: The automaton state after the step.
    fsa_state: int
    #: The task is done (accepting state; Safety-Gymnasium: a goal was met this step).
    success: bool
    #: The automaton is in its trap (the formula's safety part broken).
    trap: bool
    #: The task reward of the step (the progress reward or Eq. 5A1).
    tl_reward: float
    #: The task's own reward where the env shapes what it pays (Safety-Gymnasium's reward).
    task_reward: float
    #: The action applied, in the env's action units.
    action: NDArray[np.float64]
    #: What the shield did (present when a shield filtered the step).
    shield: ShieldInfo
    #: Each user barrier's value at the new state (:class:`tlshield.wrappers.Shielded`).
    barriers: dict[str, float]
    #: The env's constraints ``{name: h}`` at the new state (the metrics' ``min_h_<name>``).
    constraints: dict[str, float]
    #: The distance from the agent to the nearest obstacle.
    min_obstacle_distance: float
    #: The agent touched an obstacle (the env's own definition).
    collision: bool
    #: The step was unsafe (the env's own definition; else measured from the barriers).
    violation: bool
    #: Safety-Gymnasium's cost of the step.
    cost: float
    #: Safety-Gymnasium: a goal was met (and a new one placed).
    goal_met: bool
    #: Safety-Gymnasium: the routed way left to the goal.
    detour: float
    #: Safety-Gymnasium: the true state the shield read.
    state: NDArray[np.float64]
    #: FlatWorld-v0: the agent left the square.
    box_exit: bool
    #: Channel-v0, after a reset: a goal lies outside the channel.
    goal_outside_channel: bool
    #: Channel-v0, after a reset: the CLF's first goal lies outside the channel.
    clf_goal_outside: bool


def shield_info(result: FilterResult, a_rl: NDArray[np.float64]) -> ShieldInfo:
    """``info["shield"]`` of a step the shield filtered: the RL action, the corrections,
    ``delta``, the status, the largest barrier ``slack``, the barrier that gave way, the
    solver, the CLF ``goal``, whether it is unreachable and the enforced ``barriers``."""
    return {
        "a_rl": a_rl,
        "a_cbf": result.a_cbf,
        "a_clf": result.a_clf,
        "delta": result.delta,
        "status": result.status,
        "slack": result.slack,
        "gave_way": result.gave_way,
        "solver": result.solver,
        "goal": result.goal,
        "goal_unreachable": result.goal_unreachable,
        "barriers": dict(result.barriers),
    }


class ShieldedStep:
    """The step of an env written in Python around a task :class:`tlshield.Monitor`:
    :meth:`filter` the RL action through the env's shield (which reads the monitor's FSA state
    and reading of the atoms), apply it in the env, :meth:`advance` the monitor on the new
    state, and build the step's ``info`` with :meth:`info`. Without a shield the RL action goes
    through as it is and ``info`` has no ``"shield"``. The shield is passed per step: the env
    owns it (and may swap it, as a CLF schedule does)."""

    def __init__(self, monitor: Monitor) -> None:
        self.monitor = monitor
        self._entry: ShieldInfo | None = None

    def filter(
        self, shield: Shield | None, a_rl: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], FilterResult | None]:
        """The action to apply (in the shield's units) and the shield's result (None without
        a shield)."""
        if shield is None:
            self._entry = None
            return a_rl, None
        result = shield.filter_monitor(self.monitor, a_rl)
        self._entry = shield_info(result, a_rl)
        return result.action, result

    def advance(self, s_next: NDArray[np.float64], restart: bool = False) -> TaskStep:
        """Moves the monitor to the new state (``restart``: the task starts again there)."""
        return self.monitor.reset(s_next) if restart else self.monitor.advance(s_next)

    def info(self, base: Mapping[str, Any] | None = None, **keys: Any) -> StepInfo:
        """The step's ``info``: ``base`` (what a wrapped env returned), then ``keys`` (the env's
        own, :class:`StepInfo`'s names, which win), then the last :meth:`filter`'s
        ``"shield"`` entry when a shield filtered."""
        info: Any = {**(base or {}), **keys}
        if self._entry is not None:
            info["shield"] = self._entry
        return info
