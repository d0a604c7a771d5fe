"""The task: the shield's settings for ``tlshield/Safety*`` and the formula it enforces.

This module owns :class:`SafetyGoalParams` (every setting a keyword override of the env takes)
and :func:`goal_spec`, ``(!h1 & ... & !hN & !v1 & ...) U goal`` over the shield's state:
hazards (and Goal2's vases) in the formula, so that its safe set keeps them out and its CLF
drives to the goal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import ClassVar

from tlshield._core import Ball, Spec


@dataclass(frozen=True)
class SafetyGoalParams:
    """The shield's settings for ``tlshield/Safety*`` (each a keyword override). The defaults
    are the Point's; a robot may set its own (:attr:`CarModel.defaults`), which a keyword
    overrides in turn."""

    #: The hazard's cost radius is 0.2 (agent centre to hazard centre); the barrier keeps
    #: this much more.
    hazard_margin: float = 0.1
    #: Keep the agent's centre this far from a vase's centre (a vase is a 0.2 m cube and the
    #: agent a 0.1 m sphere with a 0.05 m box ahead: touching needs at most 0.32 m).
    vase_radius: float = 0.4
    #: HOCBF gains, the CLF's and the QP's. The defaults are the settings at which the shield
    #: alone meets the most goals (docs/guides/safety-gym.md, "The defaults": tuned on reset
    #: seeds 900-905, measured on 700-709): a CLF at full thrust (``clf_bound = 1``) with a
    #: fast decay (``c3``, ``clf_gain``), and a HOCBF that lets it close on a hazard at
    #: ``alpha = 2``.
    alpha: float = 2.0
    alpha2: float = 4.0
    c3: float = 5.0
    k: float = 1e4
    clf_gain: float = 3.0
    #: Box on a_clf (the CLF's thrust), in units of full thrust.
    clf_bound: float = 1.0
    #: Barriers are kept this far above 0 (in h = distance - radius, metres).
    margin: float = 0.02
    #: The router's clearance: it plans around each avoided disc grown by this fraction of
    #: its radius (``Shield(route_clearance=...)``); at 1 its tangents leave the discs room
    #: to pass at speed.
    route_clearance: float = 1.0
    #: The shield's ``disturbance`` bounds: the model's one-step error on the position's
    #: rate (m/s, on ``x, y``) and on the velocity's rate (m/s^2, on ``vx, vy``), from
    #: ``scripts/safety_gym_model.py`` (0 turns a bound off).
    position_error: float = 0.05
    velocity_error: float = 0.0
    #: The bound on the heading's rate error (rad/s; the Car's turn lags its command).
    heading_error: float = 0.0
    #: Paid per step as ``correction_penalty * |u - u_rl|`` (the shield's correction in its
    #: units, thrust and turn in ``[-1, 1]``), taken off the reward PPO learns from
    #: (Krasowski et al. 2023); ``info["task_reward"]`` keeps Safety-Gymnasium's reward, which
    #: every table reports. 0 (the default) pays nothing.
    correction_penalty: float = 0.0
    #: With ``sensing="lidar"``, every hazard's and vase's barrier radius grows by this (m),
    #: beyond the bound the lidar's points already keep for the robot's motion between
    #: readings (computed each step from the velocimeter,
    #: :mod:`~tlshield.envs.safety_gym.sensing`): a margin of one's own. 0 by default.
    lidar_slack: float = 0.0

    #: The settings that may be 0 (every other one must be > 0).
    _MAY_BE_ZERO: ClassVar[tuple[str, ...]] = (
        "position_error",
        "velocity_error",
        "heading_error",
        "correction_penalty",
        "lidar_slack",
    )

    def check(self) -> None:
        """Raises ValueError naming the first bad setting."""
        for f in fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and math.isfinite(v)):
                raise ValueError(f"{f.name} = {v!r}: expected a finite number")
            if f.name in self._MAY_BE_ZERO and v < 0:
                raise ValueError(f"{f.name} = {v!r}: expected a number >= 0")
            if f.name not in self._MAY_BE_ZERO and v <= 0:
                raise ValueError(f"{f.name} = {v!r}: expected a number > 0")


def goal_spec(
    hazards: int,
    vases: int,
    params: SafetyGoalParams,
    agent_dim: int = 5,
    pivot: float = 0.0,
    slack: float = 0.0,
) -> Spec:
    """``(!h1 & ... & !v1 & ...) U goal`` over the shield's state: the agent's ``agent_dim``
    values, the goal's ``x, y``, then two values per hazard and per vase (the objects' centres
    are read from the state, so one spec serves every layout). With ``pivot`` > 0 the hazards
    and vases hold the point ``pivot`` ahead of ``x, y`` along the heading ``s[2]``; ``slack``
    grows their radii (m)."""
    # The goal is 0.3 m in Safety-Gymnasium; 0.25 here, so that Safety-Gymnasium meets it (and
    # places the next one, which restarts the task) before the automaton accepts.
    goal = [agent_dim, agent_dim + 1]
    preds: dict[str, Ball] = {"goal": Ball(pos=[0, 1], radius=0.25, center_dims=goal)}
    radius = {"h": 0.2 + params.hazard_margin + slack, "v": params.vase_radius + slack}
    start = agent_dim + 2
    for kind, count in (("h", hazards), ("v", vases)):
        for i in range(count):
            body = {"heading": 2, "offset": (pivot, 0.0)} if pivot > 0 else {}
            preds[f"{kind}{i + 1}"] = Ball(
                pos=[0, 1], radius=radius[kind], center_dims=[start, start + 1], **body
            )
            start += 2
    avoid = " & ".join(f"!{name}" for name in preds if name != "goal")
    return Spec(f"({avoid}) U goal", preds)
