"""The paper's case study (Li & Belta, Sec. VI): a channel, three goals, two moving obstacles.

State (13 values): reference point ``x, y``, heading ``theta``, goal centres ``g1, g2, g3``
(x, y each) and obstacle centres ``o1, o2`` (x, y each). The action is ``(a_v, a_theta)`` of
the unicycle's reference point, normalised to ``[-1, 1]^2`` (scaled to
``ChannelConfig.rl_bounds``; ``info["shield"]["a_rl"]`` is in physical units).

Observation (``ChannelConfig.observation``): ``"relative"`` (default, 20 values + the one-hot
FSA state): ``cos theta, sin theta``, the two channel constraints ``c1, c2``, the goals and
the obstacles relative to the agent and the obstacles' velocities (measured from their last
two positions) and the automaton's next goal (Eq. 5B1, zero in acceptance), all in the
agent's frame (x ahead, y to the left); ``"paper"``: the 13 state values followed by the
one-hot FSA state.

Every constant of the environment is a field of :class:`ChannelConfig` (documented there) and
can be overridden by keyword in ``gymnasium.make("tlshield/Channel-v0", ...)``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, fields, replace
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from tlshield._core import Ball, ChannelWorld, Halfspace, Shield, Spec, Unicycle
from tlshield.envs.layout import GOAL_DIMS, OBSTACLE_DIMS, STATE_DIM, THETA, X, Y
from tlshield.tracking import FsaTracker, shield_info

#: The task: visit g1 or g2, then g3, staying inside the channel until g3 (paper Eq. 6C1).
TASK = "(F g1 | F g2) & F g3 & (!g3 U (g1 | g2)) & ((c1 & c2) U g3)"


#: Observation layouts (see the module docs).
OBSERVATIONS = ("relative", "paper")
#: Length of the relative observation before the one-hot FSA state.
RELATIVE_DIM = 20

#: The four configurations of the paper: which parts of the shield are on.
CONFIGS = {
    "rl": (False, False),
    "rl_cbf": (True, False),
    "rl_clf": (False, True),
    "rl_cbf_clf": (True, True),
}

SQRT2 = math.sqrt(2.0)


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


@dataclass(frozen=True)
class ChannelConfig:
    """Every constant of the case study. Lengths in metres, times in seconds, angles in
    radians. Positions use channel coordinates where convenient: ``u`` along the channel's
    centre line ``y = x`` from the origin, ``v`` across it (``v = (y - x) / sqrt(2)``)."""

    # --- geometry -------------------------------------------------------------------------
    #: ``w`` of the channel constraints ``c1: x - y + w > 0``, ``c2: y - x + w > 0``; the
    #: channel's half-width across is ``w / sqrt(2)`` (1.06 m).
    half_width: float = 1.5
    #: Radius of the goal discs g1, g2, g3.
    goal_radius: float = 0.5
    #: The arena ``[lo, hi]^2``: the reference point is kept inside (a wall), and rewards are
    #: bounded because of it.
    arena: tuple[float, float] = (-3.0, 13.0)
    #: ``u`` ranges of the goal centres: g1 and g2 first, g3 further along.
    near_goal_u: tuple[float, float] = (2.5, 5.5)
    far_goal_u: tuple[float, float] = (7.5, 9.0)
    #: ``|v|`` range of a goal drawn outside the channel (its whole disc is outside).
    outside_goal_v: tuple[float, float] = (1.66, 2.5)
    #: Probability that the second of g1/g2 lies outside the channel (the other and g3 are
    #: always inside, so every episode is solvable).
    outside_goal_probability: float = 0.5

    # --- agent ----------------------------------------------------------------------------
    #: Distance of the reference point ahead of the unicycle's centre (Eq. 6A2).
    eps: float = 0.1
    #: Euler step. ``alpha * dt`` must stay <= 1 (discrete-time CBF).
    dt: float = 0.1
    #: Episode length in steps (the paper's horizon).
    horizon: int = 200
    #: The RL action box (a_v in m/s, a_theta in rad/s): the policy's action space.
    rl_bounds: tuple[tuple[float, float], tuple[float, float]] = ((-1.0, -2.0), (1.0, 2.0))
    #: Start: reference point at ``u in [-start_spread, start_spread]``, ``|v| <= start_spread``,
    #: heading ``pi/4 +- start_heading``.
    start_spread: float = 0.3
    start_heading: float = 0.5

    # --- obstacles ------------------------------------------------------------------------
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

    #: Beyond the paper: put the obstacles in the formula (``TASK_WITH_OBSTACLES``), so the
    #: CBF also keeps the agent out of them (ignoring their motion, which it does not know).
    obstacles_in_task: bool = False
    #: Beyond the paper: the obstacles are barriers of the shield (``h = |p - o| -
    #: barrier_radius``) whose centres move with the velocity the environment measured from
    #: their last two positions (``Shield.filter(..., drift=...)``).
    obstacle_barrier: bool = True
    #: Radius kept around each obstacle centre by the moving-obstacle barrier.
    barrier_radius: float = 0.45
    #: Whether the shield is told the obstacles' measured velocity (off: the barrier treats
    #: them as standing still at each step, for comparison).
    obstacle_drift: bool = True

    # --- observation ----------------------------------------------------------------------
    #: ``"relative"`` or ``"paper"`` (see the module docs).
    observation: str = "relative"

    # --- reward ---------------------------------------------------------------------------
    #: ``"progress"`` (the progress-aware task reward, :class:`tlshield.ProgressReward`) or
    #: ``"paper"`` (Eq. 5A1 with ``trap_penalty``).
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
    #: Weight of the obstacle term: reward = r_tl + w * min(d - safe_distance, 0)
    #: - collision_penalty * [d < obstacle_radius].
    w: float = 0.05
    #: Paid on every step in collision (training does not end on a collision, so barging
    #: through an obstacle must cost more than the detour around it).
    collision_penalty: float = 1.0
    #: Paid per step as ``intervention_penalty * |a_cbf|^2`` (physical units) when the shield
    #: runs inside the environment, to teach an agent not to lean on the shield. Off by
    #: default: the README's ablation measured it costing success (0.93 -> 0.87 with the
    #: paper's PPO; 0.87 -> 0.84 with the default preset, 2 seeds each).
    intervention_penalty: float = 0.0

    # --- shield (Eq. 5D2) -----------------------------------------------------------------
    alpha: float = 2.0
    c3: float = 1.0
    K: float = 1e4
    #: Box on a_cbf: at least the RL box plus the CLF box, so stopping is always feasible.
    cbf_bounds: tuple[tuple[float, float], tuple[float, float]] = ((-1.5, -3.0), (1.5, 3.0))
    #: The shield keeps every barrier above this (not just >= 0: an atom holds iff rho > 0).
    cbf_margin: float = 1e-3
    #: Box on a_clf: narrow, so the RL action can overpower the CLF (paper Sec. VI-E).
    clf_bounds: tuple[tuple[float, float], tuple[float, float]] = ((-0.3, -0.6), (0.3, 0.6))

    @property
    def trap_penalty(self) -> float:
        """Per-step Eq. 5A1 reward in the trap: no better than the worst task reward reachable
        outside it (every atom's robustness in the arena is above minus the arena's diagonal).
        The progress reward has its own (``ProgressReward.trap_penalty``)."""
        lo, hi = self.arena
        return -max(1.0, self.c_r) * (hi - lo) * SQRT2

    def check(self) -> None:
        """Raises ValueError naming the first bad constant."""
        positive = (
            "half_width",
            "goal_radius",
            "eps",
            "dt",
            "obstacle_radius",
            "c_r",
            "alpha",
            "c3",
            "K",
        )
        for name in positive:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} = {value!r}: expected a finite number > 0")
        if not (isinstance(self.horizon, int) and self.horizon > 0):
            raise ValueError(f"horizon = {self.horizon!r}: expected a positive integer")
        if self.alpha * self.dt > 1.0:
            raise ValueError(
                f"alpha * dt = {self.alpha * self.dt:g} > 1: the discrete-time CBF condition "
                "needs alpha * dt <= 1"
            )
        if not (math.isfinite(self.w) and self.w >= 0):
            raise ValueError(f"w = {self.w!r}: expected a finite number >= 0")
        for name, value, allowed in (
            ("observation", self.observation, OBSERVATIONS),
            ("reward", self.reward, ("progress", "paper")),
        ):
            if value not in allowed:
                raise ValueError(f"{name} = {value!r}: expected one of {allowed}")
        if not (0.0 < self.gamma <= 1.0):
            raise ValueError(f"gamma = {self.gamma!r}: expected a discount in (0, 1]")
        for name in ("progress_scale", "barrier_radius"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} = {value!r}: expected a finite number > 0")
        for name in ("bonus", "collision_penalty", "intervention_penalty"):
            value = getattr(self, name)
            if name == "bonus" and value is None:
                continue
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} = {value!r}: expected a finite number >= 0")
        inside = self.half_width / SQRT2
        if self.goal_radius >= inside:
            raise ValueError(
                f"half_width = {self.half_width!r}, goal_radius = {self.goal_radius!r}: a goal "
                f"disc must fit inside the channel, i.e. half_width / sqrt(2) = {inside:.3g} > "
                "goal_radius"
            )
        if self.outside_goal_v[0] < inside + self.goal_radius:
            raise ValueError(
                f"outside_goal_v = {self.outside_goal_v!r}: a goal drawn outside the channel must "
                "lie wholly outside it, i.e. outside_goal_v[0] >= half_width / sqrt(2) + "
                f"goal_radius = {inside + self.goal_radius:.3g}"
            )
        lo, hi = np.asarray(self.rl_bounds, dtype=float)
        if lo.shape != (2,) or hi.shape != (2,) or np.any(lo >= hi):
            raise ValueError(
                f"rl_bounds = {self.rl_bounds!r}: expected ((lo_v, lo_w), (hi_v, hi_w))"
            )
        if not (math.isfinite(self.cbf_margin) and self.cbf_margin > 0):
            raise ValueError(
                f"cbf_margin = {self.cbf_margin!r}: expected a finite number > 0 (an atom holds "
                "only while rho > 0, so a barrier kept at h >= 0 lets the discrete-time plant "
                "settle at h = 0 or just below it)"
            )
        # The shield's own checks, with these settings (the CBF box must cancel every RL plus
        # CLF action): refused here, where the setting is given, not at the first episode.
        channel_shield(self, "rl_cbf_clf")


def task_spec(cfg: ChannelConfig) -> Spec:
    """The task spec a configuration runs with."""
    radius = cfg.obstacle_radius if cfg.obstacles_in_task else None
    return channel_task_spec(cfg.half_width, cfg.goal_radius, radius)


def _config(overrides: dict[str, Any]) -> ChannelConfig:
    names = {f.name for f in fields(ChannelConfig)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise TypeError(f"unknown Channel-v0 parameter(s) {unknown}; known: {sorted(names)}")
    cfg = replace(ChannelConfig(), **overrides)
    cfg.check()
    return cfg


#: The paper's settings (its reward and 13-value observation, no moving-obstacle barrier).
PAPER_ENV = {
    "reward": "paper",
    "observation": "paper",
    "obstacle_barrier": False,
    "w": 1.0,
    "collision_penalty": 0.0,
    "intervention_penalty": 0.0,
    "gamma": 0.99,
}


#: Slack weight of the obstacle barriers: when the channel and an obstacle cannot both hold,
#: the obstacle's row gives way, never the task's channel.
OBSTACLE_SLACK_WEIGHT = 1e-3


def obstacle_barriers(cfg: ChannelConfig) -> dict[str, tuple[Ball, float]]:
    """The moving-obstacle barriers: keep the reference point out of a disc of
    ``barrier_radius`` around each obstacle centre (read from the state)."""
    return {
        f"!o{k + 1}": (
            Ball(pos=[X, Y], radius=cfg.barrier_radius, center_dims=list(dims)),
            OBSTACLE_SLACK_WEIGHT,
        )
        for k, dims in enumerate(OBSTACLE_DIMS)
    }


def channel_model(cfg: ChannelConfig) -> Unicycle:
    """The unicycle reference point of the case study (Eq. 6A2): the environment's plant and
    the shield's model."""
    return Unicycle(cfg.eps, X, Y, THETA)


def channel_shield(cfg: ChannelConfig, config: str, spec: Spec | None = None) -> Shield | None:
    """The shield of a configuration (None for ``"rl"``)."""
    use_cbf, use_clf = CONFIGS[config]
    if not (use_cbf or use_clf):
        return None
    return Shield(
        spec or task_spec(cfg),
        channel_model(cfg),
        alpha=cfg.alpha,
        c3=cfg.c3,
        K=cfg.K,
        cbf_bounds=cfg.cbf_bounds,
        clf_bounds=cfg.clf_bounds,
        rl_bounds=cfg.rl_bounds,
        use_cbf=use_cbf,
        use_clf=use_clf,
        margin=cfg.cbf_margin,
        barriers=obstacle_barriers(cfg) if cfg.obstacle_barrier else None,
    )


class ChannelEnv(gym.Env[NDArray[np.float64], NDArray[np.float64]]):
    """``tlshield/Channel-v0``: the paper's case study (Li & Belta, Sec. VI) as one Gymnasium
    environment.

    ## Description

    A unicycle (its reference point ``eps`` ahead of the centre, Eq. 6A2) must visit g1 or g2,
    then g3, staying inside the diagonal channel ``|x - y| < w`` until it reaches g3
    (:data:`TASK`). Two obstacles oscillate across the channel. One of g1/g2 may lie outside
    the channel (a goal the task cannot take without violating it); g3 and the other are always
    inside, so every episode is solvable. The CBF/CLF shield of the configuration corrects the
    agent's action before the plant applies it.

    ## Action Space

    ``Box(-1, 1, (2,), float64)``: the forward speed ``a_v`` and turn rate ``a_theta`` of the
    reference point, scaled to ``ChannelConfig.rl_bounds`` (by default +-1 m/s and +-2 rad/s).
    With ``shield_in_env=False`` ``step`` takes the applied action in physical units instead.

    ## Observation Space

    ``ChannelConfig.observation = "relative"`` (default): 20 values then the one-hot automaton
    state -- ``cos theta, sin theta``, the channel constraints ``c1, c2``, the three goals and
    the two obstacles relative to the agent, the obstacles' velocities and the automaton's next
    goal (Eq. 5B1, zero in acceptance), in the agent's frame (x ahead, y to the left).
    ``"paper"``: the 13 state values ``[x, y, theta, g1, g2, g3, o1, o2]`` then the one-hot
    automaton state.

    ## Rewards

    ``r = r_tl + w * min(d - safe_distance, 0) - collision_penalty * [d < obstacle_radius]``,
    ``d`` the distance to the nearer obstacle. ``r_tl`` is the progress-aware task reward
    (``reward="progress"``, default: finishing always out-earns dawdling, the trap is the worst)
    or the paper's Eq. 5A1 (``reward="paper"``). ``info["tl_reward"]`` is ``r_tl``.

    ## Starting State

    The reference point within ``start_spread`` of the origin, heading ``pi/4 +-
    start_heading``; goals and obstacles drawn from the reset seed (``reset(seed=...)``).

    ## Episode End

    Terminated on success (the automaton accepts). Truncated at ``horizon`` steps (200). With
    ``evaluation=True`` (the paper's evaluation rules) the episode also terminates on a
    collision and the CBF is on in every configuration. Training does not end on collisions or
    violations: they cost reward.

    ## Arguments

    ``config``: the shield, one of "rl", "rl_cbf", "rl_clf", "rl_cbf_clf" (default).
    ``evaluation``: the paper's evaluation rules (above). ``render_mode``: "rgb_array" or
    "human". ``shield_in_env``: False leaves the shield to a vectorised wrapper
    (:class:`tlshield.wrappers.ShieldedVecEnv` or ``ShieldedVectorEnv`` with
    ``action_fn=env.rl_action``), which shields all sub-environments in one call. Any
    :class:`ChannelConfig` field is a keyword override, checked here (a ValueError names it)::

        gymnasium.make("tlshield/Channel-v0", config="rl_cbf", observation="paper")

    ## Info

    ``fsa_state``, ``success``, ``trap``, ``constraints`` (``c1``, ``c2``),
    ``min_obstacle_distance``, ``collision``, ``violation``; after a step also ``action`` (the
    applied action), ``tl_reward`` and ``shield`` (``a_rl``, ``a_cbf``, ``a_clf``, ``delta``,
    ``status``); after a reset ``goal_outside_channel`` and ``clf_goal_outside``.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array", "human"], "render_fps": 10}

    def __init__(
        self,
        config: str = "rl_cbf_clf",
        evaluation: bool = False,
        render_mode: str | None = None,
        shield_in_env: bool = True,
        **overrides: Any,
    ) -> None:
        if config not in CONFIGS:
            raise ValueError(f"config = {config!r}: expected one of {sorted(CONFIGS)}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode = {render_mode!r}: expected 'rgb_array', 'human' or None"
            )
        self.cfg = _config(overrides)
        self.config = config
        self.evaluation = evaluation
        self.render_mode = render_mode
        cfg = self.cfg
        self.spec_tl = task_spec(cfg)
        self._channel_atoms = (self.spec_tl.atoms.index("c1"), self.spec_tl.atoms.index("c2"))
        shield_config = config
        if evaluation and not CONFIGS[config][0]:
            shield_config = "rl_cbf_clf" if CONFIGS[config][1] else "rl_cbf"
        #: The plant; the shield is built on the same model.
        self.model = channel_model(cfg)
        self.shield = channel_shield(cfg, shield_config, self.spec_tl)
        self.shield_in_env = shield_in_env
        automaton = self.spec_tl.automaton()
        progress = None
        if cfg.reward == "progress":
            # Goal discs never overlap (the draw keeps them apart), so one state cannot count as
            # reaching two goals: g3 is two transitions away from the start, not one.
            progress = automaton.progress_reward(
                gamma=cfg.gamma,
                horizon=cfg.horizon,
                scale=cfg.progress_scale,
                bonus=cfg.bonus,
                c_r=cfg.c_r,
                exclusive=[["g1", "g2", "g3"]],
            )
        self.tracker = FsaTracker(automaton, cfg.c_r, cfg.trap_penalty, progress)
        lo, hi = cfg.arena
        margin = max(cfg.outside_goal_v[1], max(cfg.obstacle_amplitude)) + cfg.goal_radius
        k = automaton.num_states
        if cfg.observation == "paper":
            obs_lo = np.full(STATE_DIM, lo - margin)
            obs_hi = np.full(STATE_DIM, hi + margin)
            obs_lo[THETA], obs_hi[THETA] = -math.pi, math.pi
        else:
            span = (hi - lo + 2 * margin) * SQRT2
            obs_lo, obs_hi = np.full(RELATIVE_DIM, -span), np.full(RELATIVE_DIM, span)
            obs_lo[:2], obs_hi[:2] = -1.0, 1.0
        self.observation_space = gym.spaces.Box(
            np.concatenate([obs_lo, np.zeros(k)]),
            np.concatenate([obs_hi, np.ones(k)]),
            dtype=np.float64,
        )
        # The policy acts in [-1, 1]^2 (what SB3 expects); a_rl = centre + action * half range.
        rl_lo, rl_hi = (np.asarray(b, dtype=np.float64) for b in cfg.rl_bounds)
        self._rl_centre, self._rl_half = (rl_hi + rl_lo) / 2, (rl_hi - rl_lo) / 2
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float64)
        #: The world the core steps: plant, obstacles, shield call, monitor, reward terms and
        #: observation in one call (this class draws the episodes and builds ``info``).
        self._world = ChannelWorld(
            self.model,
            dt=cfg.dt,
            horizon=cfg.horizon,
            arena=cfg.arena,
            half_width=cfg.half_width,
            obstacle_radius=cfg.obstacle_radius,
            safe_distance=cfg.safe_distance,
            w=cfg.w,
            collision_penalty=cfg.collision_penalty,
            intervention_penalty=cfg.intervention_penalty,
            relative=cfg.observation == "relative",
            rl_bounds=cfg.rl_bounds,
            obstacle_drift=cfg.obstacle_drift,
            evaluation=evaluation,
            channel_atoms=self._channel_atoms,
        )
        #: The barrier slack of the last shielded step (> 0 only when the QP was relaxed).
        self.last_slack = 0.0
        self._obstacles = np.zeros((2, 4))  # per obstacle: u, amplitude, frequency, phase
        self._trajectory: list[NDArray[np.float64]] = []
        self._renderer: Any = None

    @property
    def state(self) -> NDArray[np.float64]:
        """The current 13-value state (a copy)."""
        return self._world.state

    @property
    def drift(self) -> NDArray[np.float64]:
        """The obstacles' motion measured over the last step (a copy), for the shield."""
        return self._world.drift

    @property
    def _t(self) -> int:
        return int(self._world.steps)

    # --- the world ------------------------------------------------------------------------

    @staticmethod
    def _xy(u: float, v: float) -> tuple[float, float]:
        return (u - v) / SQRT2, (u + v) / SQRT2

    def _draw_goals(self) -> tuple[NDArray[np.float64], bool]:
        """g3 and one of g1/g2 inside the channel; the other outside with the configured
        probability. Returns the (3, 2) centres and whether one lies outside."""
        cfg, rng = self.cfg, self.np_random
        inside_v = cfg.half_width / SQRT2 - cfg.goal_radius
        outside = bool(rng.random() < cfg.outside_goal_probability)
        k = int(rng.integers(2))
        while True:
            us = rng.uniform(*cfg.near_goal_u, size=2)
            vs = rng.uniform(-inside_v, inside_v, size=2)
            if outside:
                vs[k] = rng.choice([-1.0, 1.0]) * rng.uniform(*cfg.outside_goal_v)
            near = np.array([self._xy(u, v) for u, v in zip(us, vs, strict=True)])
            if np.linalg.norm(near[0] - near[1]) >= 2 * cfg.goal_radius + 0.2:
                break
        far = self._xy(rng.uniform(*cfg.far_goal_u), rng.uniform(-inside_v, inside_v))
        return np.vstack([near, far]), outside

    def _measure(self) -> dict[str, Any]:
        c1, c2, d, collision, violation = self._world.measure(self.tracker.monitor)
        return {
            "constraints": {"c1": c1, "c2": c2},
            "min_obstacle_distance": d,
            "collision": collision,
            "violation": violation,
        }

    def rl_action(self, action: NDArray[np.float64]) -> NDArray[np.float64]:
        """The RL action ``(a_v, a_theta)`` in physical units of policy actions in
        ``[-1, 1]^2`` (clipped); works on one action or a batch ``(N, 2)``."""
        return self._rl_centre + np.clip(action, -1.0, 1.0) * self._rl_half

    # --- Gymnasium API ------------------------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float64], dict[str, Any]]:
        super().reset(seed=seed)
        cfg, rng = self.cfg, self.np_random
        goals, outside = self._draw_goals()
        for i in range(2):
            self._obstacles[i] = (
                rng.uniform(*cfg.obstacle_u),
                rng.uniform(*cfg.obstacle_amplitude),
                rng.uniform(*cfg.obstacle_frequency),
                rng.uniform(0.0, 2 * math.pi),
            )
        if options and "obstacles" in options:
            # Given paths (u, amplitude, frequency, phase) replace the drawn ones; the draws
            # still happen, so the rest of the episode is the seed's.
            paths = np.asarray(options["obstacles"], dtype=np.float64)
            if paths.shape != (2, 4) or not np.all(np.isfinite(paths)):
                raise ValueError(
                    "options['obstacles']: expected finite (2, 4) paths (u, amplitude, "
                    f"frequency, phase), got {paths.tolist()}"
                )
            self._obstacles[:] = paths
        s = np.zeros(STATE_DIM)
        s[X], s[Y] = self._xy(
            rng.uniform(-cfg.start_spread, cfg.start_spread),
            rng.uniform(-cfg.start_spread, cfg.start_spread),
        )
        s[THETA] = math.pi / 4 + rng.uniform(-cfg.start_heading, cfg.start_heading)
        for k, (a, b) in enumerate(GOAL_DIMS):
            s[a], s[b] = goals[k]
        # The world places the obstacles on their paths and measures their velocity over the
        # step before the start (one model of their motion: the core's).
        self._world.reset(s, self._obstacles)
        s = self.state
        self._trajectory = [s[X : Y + 1].copy()]
        q = self.tracker.reset(s)
        goal = self.tracker.goal
        info = {
            "fsa_state": q,
            "success": self.tracker.success,
            "trap": self.tracker.trapped,
            "goal_outside_channel": outside,
            # Whether the goal the CLF heads for first lies outside the channel.
            "clf_goal_outside": bool(goal is not None and abs(goal[1] - goal[0]) > cfg.half_width),
            **self._measure(),
        }
        if self.render_mode == "human":
            self.render()
        return self._world.observe(self.tracker.monitor), info

    def step(
        self, action: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], float, bool, bool, dict[str, Any]]:
        # One call into the core: the RL action scaled from [-1, 1] (unless a vector shield
        # wrapper already scaled, shielded and passed the applied action), the shield reusing
        # the monitor's reading, the plant through the shield's own model, the obstacles, the
        # monitor, the reward terms and the observation.
        shield = self.shield if self.shield_in_env else None
        out = self._world.step(action, self.tracker.monitor, shield, scale=self.shield_in_env)
        if out.shield is not None:
            self.last_slack = out.shield.slack
        if self.render_mode is not None:
            self._trajectory.append(self.state[X : Y + 1])
        info = {
            "fsa_state": out.q,
            "action": out.action,
            "success": out.accepted,
            "trap": out.trapped,
            "tl_reward": out.tl_reward,
            "constraints": {"c1": out.c1, "c2": out.c2},
            "min_obstacle_distance": out.min_obstacle_distance,
            "collision": out.collision,
            "violation": out.violation,
            "shield": shield_info(out.shield, out.a_rl),
        }
        if self.render_mode == "human":
            self.render()
        return out.observation, out.reward, out.terminated, out.truncated, info

    def render(self) -> NDArray[np.uint8] | None:
        if self.render_mode is None:
            gym.logger.warn("render() without a render_mode; pass render_mode='rgb_array'")
            return None
        from tlshield.envs.render import ChannelRenderer, Scene

        if self._renderer is None:
            lo, hi = self.cfg.arena
            scene = Scene(
                half_width=self.cfg.half_width,
                goal_radius=self.cfg.goal_radius,
                obstacle_radius=self.cfg.obstacle_radius,
                arena=(lo, hi, lo, hi),
            )
            self._renderer = ChannelRenderer(scene)
        frame = self._renderer.frame(
            self.state, np.array(self._trajectory), self.tracker.q, self._t, title=self.config
        )
        if self.render_mode == "human":
            self._renderer.show(frame)
            return None
        return frame

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
