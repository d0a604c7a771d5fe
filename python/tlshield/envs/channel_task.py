"""The paper's case study as data: its task (:data:`TASK`), its four configurations
(:data:`CONFIGS`), its constants (:class:`ChannelParams`) and the core objects built from them
(the task spec, the unicycle model, the obstacle barriers and the shield).
:mod:`tlshield.envs.channel` is the Gymnasium environment around them.

The constants come in five parts: the task (channel, goals, horizon,
task reward), the agent (the unicycle and its action box), the obstacles (their motion and
reward term), the shield (Eq. 5D2 and what it is told of the obstacles) and the observation.

Lengths in metres, times in seconds, angles in radians. Positions use channel coordinates where
convenient: ``u`` along the channel's centre line ``y = x`` from the origin, ``v`` across it
(``v = (y - x) / sqrt(2)``).

Every field has one flat name (:data:`FLAT`), which is what ``gymnasium.make(..., name=value)``,
``tlshield train --set name=value``, the tuner and a run's record speak: the field's own name,
but ``observation`` for :attr:`ChannelObservation.kind`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from tlshield._core import Avoid, Ball, Halfspace, Shield, Spec, Unicycle
from tlshield.envs.layout import GOAL_DIMS, OBSTACLE_DIMS, STATE_DIM, THETA, X, Y
from tlshield.envs.params import CONFIGS, FULL

#: Observation layouts (see :mod:`tlshield.envs.channel`).
OBSERVATIONS = ("relative", "paper")
#: Task rewards: the progress-aware one (:class:`tlshield.ProgressReward`) or Eq. 5A1.
REWARDS = ("progress", "paper")
SQRT2 = math.sqrt(2.0)

Box = tuple[tuple[float, float], tuple[float, float]]


#: The least gap (m) between the edges of g1 and g2.
GOAL_GAP = 0.2


@dataclass(frozen=True)
class ChannelTask:
    """The channel, the goals, the horizon and the task reward."""

    #: ``w`` of the channel constraints ``c1: x - y + w > 0``, ``c2: y - x + w > 0``; the
    #: channel's half-width across is ``w / sqrt(2)`` (1.06 m).
    half_width: float = 1.5
    #: Radius of the goal discs g1, g2, g3.
    goal_radius: float = 0.5
    #: ``u`` ranges of the goal centres: g1 and g2 first, g3 further along.
    near_goal_u: tuple[float, float] = (2.5, 5.5)
    far_goal_u: tuple[float, float] = (7.5, 9.0)
    #: ``|v|`` range of a goal drawn outside the channel (its whole disc is outside).
    outside_goal_v: tuple[float, float] = (1.66, 2.5)
    #: Probability that the second of g1/g2 lies outside the channel (the other and g3 are
    #: always inside, so every episode is solvable).
    outside_goal_probability: float = 0.5
    #: Episode length in steps (the paper's horizon).
    horizon: int = 200
    #: ``"progress"`` (the progress-aware task reward, :class:`tlshield.ProgressReward`) or
    #: ``"paper"`` (Eq. 5A1 with the trap penalty).
    reward: str = "progress"
    #: The discount the progress reward's bonus is sized for (the trainer's gamma).
    gamma: float = 0.999
    #: Eq. 5A1 scale of the progress reward's potential (m): its shaping is clipped beyond.
    progress_scale: float = 2.0
    #: Paid on finishing the task (progress reward); None: the least bonus that makes every
    #: trajectory finishing within the horizon out-earn every one that does not, times a margin
    #: (``ProgressReward.bonus``).
    bonus: float | None = None
    #: Weight of the trap term in Eq. 5A1.
    c_r: float = 1.0
    #: The progress reward's goal term: potential per metre of approach to the automaton's CLF
    #: goal (the goal that advances the task), potential-based shaping that gives every
    #: configuration the CLF's information without its push; 0 leaves it out. 0.5: rl_cbf
    #: kept 0.90-0.99 on the 5 tuning seeds at 600 updates; without the term it kept >= 0.90
    #: on 1 of 5 at 300 updates and on none at 600 (0.25 and 1 did worse; docs/learning.md).
    goal_weight: float = 0.5
    #: Distance (m) beyond which the goal term is flat (at least the distance between goals).
    goal_span: float = 12.0
    #: End a training episode on entering the trap (leaving the channel before g3): the task
    #: can no longer be done. The step entering it also pays the trap's task reward for every
    #: step left to the horizon, so ending a bad episode early never pays. Evaluation episodes
    #: never reach the trap (the CBF is on). On: rl_clf kept >= 0.90 on 3 of the 5 tuning seeds,
    #: 1 of 5 without it; the shielded configurations never enter the trap (unchanged).
    end_on_trap: bool = True


@dataclass(frozen=True)
class ChannelAgent:
    """The unicycle: its model, its action box, its arena and its start."""

    #: Distance of the reference point ahead of the unicycle's centre (Eq. 6A2).
    eps: float = 0.1
    #: Euler step. ``alpha * dt`` must stay <= 1 (discrete-time CBF).
    dt: float = 0.1
    #: The RL action box (a_v in m/s, a_theta in rad/s): the policy's action space.
    rl_bounds: Box = ((-1.0, -2.0), (1.0, 2.0))
    #: The arena ``[lo, hi]^2``: the reference point is kept inside (a wall), and rewards are
    #: bounded because of it.
    arena: tuple[float, float] = (-3.0, 13.0)
    #: Start: reference point at ``u in [-start_spread, start_spread]``, ``|v| <= start_spread``,
    #: heading ``pi/4 +- start_heading``.
    start_spread: float = 0.3
    start_heading: float = 0.5


@dataclass(frozen=True)
class ChannelObstacles:
    """The two moving obstacles and the reward's obstacle term."""

    #: Collision when the reference point is closer than this to an obstacle centre.
    obstacle_radius: float = 0.3
    #: The obstacle reward term is ``w * min(d - safe_distance, 0)``.
    safe_distance: float = 0.8
    #: Obstacles oscillate across the channel around ``u`` in this range ...
    obstacle_u: tuple[float, float] = (3.0, 7.0)
    #: ... with an amplitude (m) and angular frequency (rad/s) drawn from these ranges (top
    #: speed 0.6 m/s, below the agent's 1 m/s, so a collision is always avoidable).
    obstacle_amplitude: tuple[float, float] = (0.8, 1.5)
    obstacle_frequency: tuple[float, float] = (0.2, 0.4)
    #: Weight of the obstacle term: reward = r_tl + w * min(d - safe_distance, 0)
    #: - collision_penalty * [d < obstacle_radius].
    w: float = 0.05
    #: Paid on every step in collision (training does not end on a collision, so barging
    #: through an obstacle must cost more than the detour around it).
    collision_penalty: float = 1.0


@dataclass(frozen=True)
class ChannelShield:
    """The shield (Eq. 5D2) and what it is told of the obstacles."""

    alpha: float = 2.0
    c3: float = 1.0
    #: The CLF relaxation cost (the paper's K).
    k: float = 1e4
    #: Box on a_cbf: at least the RL box plus the CLF box, so stopping is always feasible.
    cbf_bounds: Box = ((-1.5, -3.0), (1.5, 3.0))
    #: The shield keeps every barrier above this (not just >= 0: an atom holds iff rho > 0).
    margin: float = 1e-3
    #: Box on a_clf: narrow, so the RL action can overpower the CLF (paper Sec. VI-E).
    clf_bounds: Box = ((-0.3, -0.6), (0.3, 0.6))
    #: Beyond the paper: the obstacles are barriers of the shield (``h = |p - o| -
    #: barrier_radius``) whose centres move with the velocity the environment measured from
    #: their last two positions (``Shield.filter(..., drift=...)``).
    obstacle_barrier: bool = True
    #: Radius kept around each obstacle centre by the moving-obstacle barrier.
    barrier_radius: float = 0.45
    #: Whether the shield is told the obstacles' measured velocity (off: the barrier treats
    #: them as standing still at each step, for comparison).
    obstacle_drift: bool = True
    #: Beyond the paper: put the obstacles in the formula (``TASK_WITH_OBSTACLES``), so the
    #: CBF also keeps the agent out of them (ignoring their motion, which it does not know).
    obstacles_in_task: bool = False
    #: Paid per step as ``intervention_penalty * |a_cbf|^2`` (physical units) when the shield
    #: runs inside the environment, to teach an agent not to lean on the shield. Off by
    #: default: the ablation (docs/reproduction.md) measured it costing success (0.93 -> 0.87
    #: with the paper's PPO; 0.87 -> 0.84 with the default preset, 2 seeds each).
    intervention_penalty: float = 0.0


@dataclass(frozen=True)
class ChannelObservation:
    """What the agent observes."""

    #: ``"relative"`` or ``"paper"`` (see :mod:`tlshield.envs.channel`); flat name
    #: ``observation``.
    kind: str = "relative"


#: The parts of :class:`ChannelParams`, by attribute.
PARTS: dict[str, type] = {
    "task": ChannelTask,
    "agent": ChannelAgent,
    "obstacles": ChannelObstacles,
    "shield": ChannelShield,
    "observation": ChannelObservation,
}
#: Flat name -> (part, field) of every constant.
FLAT: dict[str, tuple[str, str]] = {
    ("observation" if part == "observation" else f.name): (part, f.name)
    for part, cls in PARTS.items()
    for f in fields(cls)
}


@dataclass(frozen=True)
class ChannelParams:
    """Every constant of the case study, in five parts (see the module docs). Build one from
    flat names with :meth:`from_flat` (what ``gymnasium.make`` does with its keywords)."""

    task: ChannelTask = field(default_factory=ChannelTask)
    agent: ChannelAgent = field(default_factory=ChannelAgent)
    obstacles: ChannelObstacles = field(default_factory=ChannelObstacles)
    shield: ChannelShield = field(default_factory=ChannelShield)
    observation: ChannelObservation = field(default_factory=ChannelObservation)

    @staticmethod
    def flat_names() -> tuple[str, ...]:
        """Every flat name, in the parts' order."""
        return tuple(FLAT)

    @classmethod
    def from_flat(cls, values: Mapping[str, Any]) -> ChannelParams:
        """The defaults with ``values`` (flat names) applied. An unknown name is a TypeError;
        the values are not checked (:meth:`check`)."""
        unknown = sorted(set(values) - set(FLAT))
        if unknown:
            raise TypeError(f"unknown parameter(s) {unknown}; known: {sorted(FLAT)}")
        by_part: dict[str, dict[str, Any]] = {}
        for name, value in values.items():
            part, name_in_part = FLAT[name]
            by_part.setdefault(part, {})[name_in_part] = value
        return cls(**{part: PARTS[part](**kw) for part, kw in by_part.items()})

    def flat(self) -> dict[str, Any]:
        """Every constant by flat name (what a run's record stores)."""
        return {name: getattr(getattr(self, part), f) for name, (part, f) in FLAT.items()}

    def replace(self, **values: Any) -> ChannelParams:
        """A copy with ``values`` (flat names) changed."""
        return ChannelParams.from_flat({**self.flat(), **values})

    # The settings every bundled environment's parameters share (training reads them).
    @property
    def horizon(self) -> int:
        """Episode length (``task.horizon``)."""
        return self.task.horizon

    @property
    def gamma(self) -> float:
        """The discount the task reward is sized for (``task.gamma``)."""
        return self.task.gamma

    @property
    def trap_penalty(self) -> float:
        """Per-step Eq. 5A1 reward in the trap: no better than the worst task reward reachable
        outside it (every atom's robustness in the arena is above minus the arena's diagonal).
        The progress reward has its own (``ProgressReward.trap_penalty``)."""
        lo, hi = self.agent.arena
        return -max(1.0, self.task.c_r) * (hi - lo) * SQRT2

    def check(self) -> None:
        """Raises ValueError naming the first bad constant (by its flat name)."""
        task, agent, shield = self.task, self.agent, self.shield
        for name in ("half_width", "goal_radius", "eps", "dt", "obstacle_radius", "c_r"):
            _positive(name, self._get(name))
        for name in ("alpha", "c3", "k", "progress_scale", "barrier_radius", "goal_span"):
            _positive(name, self._get(name))
        if not (isinstance(task.horizon, int) and task.horizon > 0):
            raise ValueError(f"horizon = {task.horizon!r}: expected a positive integer")
        if shield.alpha * agent.dt > 1.0:
            raise ValueError(
                f"alpha * dt = {shield.alpha * agent.dt:g} > 1: the discrete-time CBF condition "
                "needs alpha * dt <= 1"
            )
        for name, value, allowed in (
            ("observation", self.observation.kind, OBSERVATIONS),
            ("reward", task.reward, REWARDS),
        ):
            if value not in allowed:
                raise ValueError(f"{name} = {value!r}: expected one of {allowed}")
        if not (0.0 < task.gamma <= 1.0):
            raise ValueError(f"gamma = {task.gamma!r}: expected a discount in (0, 1]")
        for name in ("w", "bonus", "collision_penalty", "intervention_penalty", "goal_weight"):
            value = self._get(name)
            if name == "bonus" and value is None:
                continue
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} = {value!r}: expected a finite number >= 0")
        inside = task.half_width / SQRT2
        if task.goal_radius >= inside:
            raise ValueError(
                f"half_width = {task.half_width!r}, goal_radius = {task.goal_radius!r}: a goal "
                f"disc must fit inside the channel, i.e. half_width / sqrt(2) = {inside:.3g} > "
                "goal_radius"
            )
        # g1 and g2 are drawn until GOAL_GAP apart: inside the channel they must fit so.
        du = task.near_goal_u[1] - task.near_goal_u[0]
        apart = 2 * task.goal_radius + GOAL_GAP
        if not (du >= 0 and math.hypot(du, 2 * (inside - task.goal_radius)) > 1.1 * apart):
            raise ValueError(
                f"near_goal_u = {task.near_goal_u!r}: g1 and g2 are drawn in it, inside the "
                f"channel, {apart:.3g} m apart centre to centre (2 goal_radius + {GOAL_GAP}); "
                "the range is too short for that (widen it)"
            )
        if task.outside_goal_v[0] < inside + task.goal_radius:
            raise ValueError(
                f"outside_goal_v = {task.outside_goal_v!r}: a goal drawn outside the channel "
                "must lie wholly outside it, i.e. outside_goal_v[0] >= half_width / sqrt(2) + "
                f"goal_radius = {inside + task.goal_radius:.3g}"
            )
        lo, hi = np.asarray(agent.rl_bounds, dtype=float)
        if lo.shape != (2,) or hi.shape != (2,) or np.any(lo >= hi):
            raise ValueError(
                f"rl_bounds = {agent.rl_bounds!r}: expected ((lo_v, lo_w), (hi_v, hi_w))"
            )
        if not (math.isfinite(shield.margin) and shield.margin > 0):
            raise ValueError(
                f"margin = {shield.margin!r}: expected a finite number > 0 (an atom holds only "
                "while rho > 0, so a barrier kept at h >= 0 lets the discrete-time plant settle "
                "at h = 0 or just below it)"
            )
        # The shield's own checks, with these settings (the CBF box must cancel every RL plus
        # CLF action): refused here, where the setting is given, not at the first episode.
        channel_shield(self, FULL)

    def _get(self, name: str) -> Any:
        part, name_in_part = FLAT[name]
        return getattr(getattr(self, part), name_in_part)


def _positive(name: str, value: Any) -> None:
    if not (
        isinstance(value, (int, float))
        and not isinstance(value, bool)
        and math.isfinite(value)
        and value > 0
    ):
        raise ValueError(f"{name} = {value!r}: expected a finite number > 0")


#: The task: visit g1 or g2, then g3, staying inside the channel until g3 (paper Eq. 6C1).
TASK = "(F g1 | F g2) & F g3 & (!g3 U (g1 | g2)) & ((c1 & c2) U g3)"


#: The task with the obstacles in the formula (an option beyond the paper): the obstacles
#: must be avoided until g3, so the CBF safe set keeps the agent out of them too.
TASK_WITH_OBSTACLES = "(F g1 | F g2) & F g3 & (!g3 U (g1 | g2)) & ((c1 & c2 & !o1 & !o2) U g3)"


@functools.lru_cache(maxsize=64)
def channel_task_spec(
    half_width: float = 1.5, goal_radius: float = 0.5, obstacle_radius: float | None = None
) -> Spec:
    """The task spec over the 13-value state, one per parameters (cached, so that every
    environment, shield and monitor of the task shares one automaton: a monitor and the shield
    that reads it must have the same one).

    Goals are balls of ``goal_radius`` around centres read from the state; the channel is
    ``c1: x - y + w > 0`` and ``c2: y - x + w > 0`` with ``w = half_width`` (paper Sec. VI).
    With ``obstacle_radius`` the formula is :data:`TASK_WITH_OBSTACLES`, ``o1``/``o2`` being
    balls of that radius around the obstacle centres.
    """
    c1 = [0.0] * STATE_DIM
    c1[X], c1[Y] = 1.0, -1.0
    c2 = [-v for v in c1]
    goals = {
        f"g{k + 1}": Ball(pos=[X, Y], radius=goal_radius, center_dims=list(dims))
        for k, dims in enumerate(GOAL_DIMS)
    }
    channel = {"c1": Halfspace(c1, half_width), "c2": Halfspace(c2, half_width)}
    # The goals' centres live in the state, so the geometry cannot tell they are disjoint.
    exclusive = [list(goals)]
    if obstacle_radius is None:
        return Spec(TASK, {**goals, **channel}, exclusive=exclusive)
    obstacles = {
        f"o{k + 1}": Ball(pos=[X, Y], radius=obstacle_radius, center_dims=list(dims))
        for k, dims in enumerate(OBSTACLE_DIMS)
    }
    return Spec(TASK_WITH_OBSTACLES, {**goals, **channel, **obstacles}, exclusive=exclusive)


def task_spec(params: ChannelParams) -> Spec:
    """The task spec a configuration runs with."""
    radius = params.obstacles.obstacle_radius if params.shield.obstacles_in_task else None
    return channel_task_spec(params.task.half_width, params.task.goal_radius, radius)


#: The paper's settings (its reward and 13-value observation, no moving-obstacle barrier).
PAPER_ENV = {
    "reward": "paper",
    "observation": "paper",
    "obstacle_barrier": False,
    "w": 1.0,
    "collision_penalty": 0.0,
    "intervention_penalty": 0.0,
    "gamma": 0.99,
    # Beyond the paper: its episodes go on in the trap, and it has no goal term.
    "end_on_trap": False,
    "goal_weight": 0.0,
}


#: Slack weight of the obstacle barriers: when the channel and an obstacle cannot both hold,
#: the obstacle's row gives way, never the task's channel.
OBSTACLE_SLACK_WEIGHT = 1e-3


def obstacle_barriers(params: ChannelParams) -> dict[str, tuple[Avoid, float]]:
    """The moving-obstacle barriers: keep the reference point out of a disc of
    ``barrier_radius`` around each obstacle centre (read from the state)."""
    return {
        f"!o{k + 1}": (
            Avoid(Ball(pos=[X, Y], radius=params.shield.barrier_radius, center_dims=list(dims))),
            OBSTACLE_SLACK_WEIGHT,
        )
        for k, dims in enumerate(OBSTACLE_DIMS)
    }


def channel_model(params: ChannelParams) -> Unicycle:
    """The unicycle reference point of the case study (Eq. 6A2): the environment's plant and
    the shield's model."""
    return Unicycle(params.agent.eps, X, Y, THETA)


def channel_shield(params: ChannelParams, config: str, spec: Spec | None = None) -> Shield | None:
    """The shield of a configuration (None for ``"rl"``)."""
    use_cbf, use_clf = CONFIGS[config]
    if not (use_cbf or use_clf):
        return None
    return Shield(
        spec or task_spec(params),
        channel_model(params),
        alpha=params.shield.alpha,
        c3=params.shield.c3,
        k=params.shield.k,
        cbf_bounds=params.shield.cbf_bounds,
        clf_bounds=params.shield.clf_bounds,
        rl_bounds=params.agent.rl_bounds,
        use_cbf=use_cbf,
        use_clf=use_clf,
        margin=params.shield.margin,
        dt=params.agent.dt,
        barriers=obstacle_barriers(params) if params.shield.obstacle_barrier else None,
    )


__all__ = [
    "CONFIGS",
    "FLAT",
    "OBSERVATIONS",
    "PAPER_ENV",
    "PARTS",
    "TASK",
    "TASK_WITH_OBSTACLES",
    "ChannelAgent",
    "ChannelObservation",
    "ChannelObstacles",
    "ChannelParams",
    "ChannelShield",
    "ChannelTask",
    "channel_model",
    "channel_shield",
    "channel_task_spec",
    "obstacle_barriers",
    "task_spec",
]
