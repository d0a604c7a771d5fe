"""``tlshield/PointMass-v0``: a double-integrator robot in a room with two round obstacles and
two goal regions; the task is to visit ``a``, then ``b``, without touching an obstacle before
``b`` (:data:`TASK`). The plant, the walls, the shield call, the task monitor, the reward and
the observation step in the core (:class:`tlshield._core.PointMassWorld`), through the core's
double integrator, which is also the shield's model; :class:`PointMassEnv` is the Gymnasium
shell (it draws the start and builds ``info``). Under an acceleration-level model a position
constraint has relative degree 2, so the shield enforces the obstacles with higher-order
barriers (``alpha2``) and drives to the goals with the second-order CLF (see
docs/concepts/hocbf.md). (FlatWorld-v0 is the worked example of an environment written in Python and
shielded with the public wrappers.)
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from tlshield._core import (
    DEFAULT_C_R,
    DEFAULT_TRAP_PENALTY,
    Automaton,
    Ball,
    DoubleIntegrator,
    PointMassWorld,
    Shield,
    Spec,
)
from tlshield.copying import IndependentCopies
from tlshield.envs.params import CONFIGS, FULL, build, check_config, shielded_config
from tlshield.step_info import StepInfo, shield_info
from tlshield.tracking import FsaTracker

#: Visit a, then b; stay out of both obstacles until b.
TASK = "F a & F b & (!b U a) & ((!o1 & !o2) U b)"


# Read from the core, which steps the world: one model of the layout (point_mass.rs).
#: The state: position ``x, y`` and velocity ``vx, vy``.
STATE_DIM: int = PointMassWorld.STATE_DIM
#: The position's and the velocity's state dimensions.
POS: tuple[int, int] = PointMassWorld.POS
VEL: tuple[int, int] = PointMassWorld.VEL


@dataclass(frozen=True)
class PointMassParams:
    """Every constant of ``tlshield/PointMass-v0`` (each a keyword override of ``make``)."""

    # --- room and task --------------------------------------------------------------------
    #: The room ``[lo, hi]^2``; the walls stop the robot (the velocity into a wall is zeroed).
    room: tuple[float, float] = (0.0, 10.0)
    #: Centres and radius of the goal regions a and b.
    goal_a: tuple[float, float] = (1.5, 8.5)
    goal_b: tuple[float, float] = (8.5, 8.5)
    goal_radius: float = 0.6
    #: Centres and radius of the obstacles: o1 between the start and a, o2 between a and b.
    obstacle_1: tuple[float, float] = (1.5, 4.8)
    obstacle_2: tuple[float, float] = (5.0, 8.5)
    obstacle_radius: float = 1.0
    #: Start: at rest, uniformly within ``start_spread`` of ``start``.
    start: tuple[float, float] = (1.5, 1.0)
    start_spread: float = 0.5

    # --- robot ----------------------------------------------------------------------------
    #: Largest acceleration per axis (m/s^2): the action box and the shield's action bounds.
    max_accel: float = 1.0
    #: Euler step (s) and episode length (steps).
    dt: float = 0.1
    horizon: int = 300

    # --- reward ---------------------------------------------------------------------------
    #: The progress reward's discount (the trainer's gamma) and Eq. 5A1 scale (m).
    gamma: float = 0.999
    progress_scale: float = 2.0
    #: The progress reward's goal term (potential per metre towards the CLF goal; 0: none) and
    #: the distance (m) beyond which it is flat (``ChannelTask.goal_weight``). Channel-v0's
    #: value, not tuned here: at 600 updates it kept rl_cbf and rl_cbf_clf at 1.00 on 3 of 3
    #: seeds and ended rl_clf at 1.00 where without it the last policy fell to 0.00
    #: (docs/learning.md).
    goal_weight: float = 0.5
    goal_span: float = 12.0
    #: Paid per step inside an obstacle (training does not end on a collision).
    collision_penalty: float = 1.0

    # --- shield (Eq. 5D2 with second-order rows) -------------------------------------------
    alpha: float = 1.0
    alpha2: float = 2.0
    c3: float = 0.5
    k: float = 1e4
    clf_gain: float = 0.5
    #: Box on a_clf: narrow, so the RL action can overpower the CLF.
    clf_bound: float = 0.3
    #: Barriers are kept this far above 0 (m), so the Euler plant's error stays outside.
    margin: float = 0.02

    def check(self) -> None:
        """Raises ValueError naming the first bad constant."""
        for f in fields(self):
            value = getattr(self, f.name)
            for v in value if isinstance(value, tuple) else (value,):
                if not (isinstance(v, (int, float)) and math.isfinite(v)):
                    raise ValueError(f"{f.name} = {value!r}: expected finite numbers")
        positive = ("goal_radius", "obstacle_radius", "max_accel", "dt", "alpha", "alpha2")
        positive += ("c3", "k", "clf_gain", "clf_bound", "progress_scale", "margin", "goal_span")
        for name in positive:
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} = {getattr(self, name)!r}: expected a number > 0")
        if not (isinstance(self.horizon, int) and self.horizon > 0):
            raise ValueError(f"horizon = {self.horizon!r}: expected a positive integer")
        if not 0.0 < self.gamma <= 1.0:
            raise ValueError(f"gamma = {self.gamma!r}: expected a discount in (0, 1]")
        if self.goal_weight < 0:
            raise ValueError(f"goal_weight = {self.goal_weight!r}: expected a number >= 0")
        lo, hi = self.room
        if not lo < hi:
            raise ValueError(f"room = {self.room!r}: expected (lo, hi) with lo < hi")
        discs = {
            "goal_a": (self.goal_a, self.goal_radius),
            "goal_b": (self.goal_b, self.goal_radius),
            "obstacle_1": (self.obstacle_1, self.obstacle_radius),
            "obstacle_2": (self.obstacle_2, self.obstacle_radius),
        }
        names = list(discs)
        for i, one in enumerate(names):
            for other in names[i + 1 :]:
                (c1, r1), (c2, r2) = discs[one], discs[other]
                if math.dist(c1, c2) <= r1 + r2:
                    raise ValueError(
                        f"{one} and {other} overlap: the task needs disjoint discs "
                        f"(centres {c1}, {c2}, radii {r1}, {r2})"
                    )


@functools.lru_cache(maxsize=64)
def point_mass_spec(params: PointMassParams | None = None) -> Spec:
    """The task spec over the state ``[x, y, vx, vy]``, one per parameters (cached, so that
    every environment, shield and monitor of the task shares one automaton: a batch's shield
    reads every env's monitor)."""
    params = params or PointMassParams()

    def disc(centre: tuple[float, float], radius: float) -> Ball:
        return Ball(pos=list(POS), radius=radius, center=list(centre))

    return Spec(
        TASK,
        {
            "a": disc(params.goal_a, params.goal_radius),
            "b": disc(params.goal_b, params.goal_radius),
            "o1": disc(params.obstacle_1, params.obstacle_radius),
            "o2": disc(params.obstacle_2, params.obstacle_radius),
        },
    )


def point_mass_shield(
    params: PointMassParams, config: str, spec: Spec | Automaton
) -> Shield | None:
    """The shield of a configuration (None for ``"rl"``): HOCBF rows for the obstacles and the
    goals' literals, the second-order CLF, the applied action kept in the acceleration box."""
    use_cbf, use_clf = CONFIGS[config]
    if not (use_cbf or use_clf):
        return None
    accel = params.max_accel
    return Shield(
        spec,
        DoubleIntegrator(pos=list(POS), vel=list(VEL)),
        alpha=params.alpha,
        alpha2=params.alpha2,
        c3=params.c3,
        k=params.k,
        cbf_bounds=(-2 * accel, 2 * accel),
        clf_bounds=(-params.clf_bound, params.clf_bound),
        action_bounds=(-accel, accel),
        rl_bounds=(-accel, accel),
        clf_gain=params.clf_gain,
        margin=params.margin,
        dt=params.dt,
        use_cbf=use_cbf,
        use_clf=use_clf,
    )


class PointMassEnv(IndependentCopies, gym.Env[NDArray[np.float64], NDArray[np.float64]]):
    """``tlshield/PointMass-v0`` (see the module docs and :func:`make_point_mass`).

    Observation: ``[x, y, vx, vy]`` then the one-hot automaton state. Action: the acceleration
    ``(ax, ay)`` in m/s^2; the shield's answer is clipped to ``[-max_accel, max_accel]``.
    Reward: the progress-aware task reward minus ``collision_penalty`` per step inside an
    obstacle. Terminated when the task is done, truncated at ``horizon`` steps. ``info``:
    ``constraints`` (``{"o1": h, "o2": h}``, distance minus radius), ``min_obstacle_distance``,
    ``collision`` and ``violation`` (the same: inside an obstacle), ``action`` (as applied),
    ``fsa_state``, ``success``, ``trap``, ``tl_reward`` and, with a shield, ``shield``.
    """

    #: The names of ``info["constraints"]`` (a batch builds ``info`` from these).
    CONSTRAINTS: ClassVar[tuple[str, str]] = ("o1", "o2")
    metadata: ClassVar[dict[str, Any]] = {"render_modes": []}

    def __init__(self, config: str = FULL, evaluation: bool = False, **overrides: Any) -> None:
        check_config(config)
        params = build(PointMassParams, overrides, "PointMass-v0")
        self.params = params
        self.config = config
        spec = point_mass_spec(params)
        automaton = spec.automaton()
        progress = automaton.progress_reward(
            gamma=params.gamma,
            horizon=params.horizon,
            scale=params.progress_scale,
            exclusive=[["a", "b", "o1", "o2"]],
            goal_weight=params.goal_weight,
            goal_span=params.goal_span,
        )
        shield_config = shielded_config(config, evaluation)
        self.shield = point_mass_shield(params, shield_config, automaton)
        # A routing shield's way is the goal term's distance (the reward and the guidance agree).
        self.tracker = FsaTracker(
            automaton, DEFAULT_C_R, DEFAULT_TRAP_PENALTY, progress, routed_by=self.shield
        )
        self._world = PointMassWorld(
            dt=params.dt,
            horizon=params.horizon,
            room=params.room,
            max_accel=params.max_accel,
            obstacles=(params.obstacle_1, params.obstacle_2),
            obstacle_radius=params.obstacle_radius,
            collision_penalty=params.collision_penalty,
        )
        lo, hi = params.room
        span = hi - lo
        k = automaton.num_states
        self.observation_space = gym.spaces.Box(
            np.concatenate([[lo, lo, -span, -span], np.zeros(k)]),
            np.concatenate([[hi, hi, span, span], np.ones(k)]),
            dtype=np.float64,
        )
        a = params.max_accel
        self.action_space = gym.spaces.Box(-a, a, shape=(2,), dtype=np.float64)

    @property
    def state(self) -> NDArray[np.float64]:
        """The current state ``[x, y, vx, vy]`` (a copy)."""
        return self._world.state

    @property
    def fsa_state(self) -> int:
        return self.tracker.q

    def _measure(self) -> dict[str, Any]:
        h1, h2, nearest, inside = self._world.measure()
        return {
            "constraints": {"o1": h1, "o2": h2},
            "min_obstacle_distance": nearest,
            "collision": inside,
            "violation": inside,
        }

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float64], dict[str, Any]]:
        super().reset(seed=seed)
        spread = self.params.start_spread
        p = np.asarray(self.params.start) + self.np_random.uniform(-spread, spread, size=2)
        s = np.array([p[0], p[1], 0.0, 0.0])
        self._world.reset(s)
        q = self.tracker.reset(s)
        info = {**self._measure(), "fsa_state": q, "success": self.tracker.success}
        info["trap"] = self.tracker.trapped
        return np.concatenate([s, self.tracker.one_hot()]), info

    def step(
        self, action: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], float, bool, bool, dict[str, Any]]:
        a_rl = np.asarray(action, dtype=np.float64)
        out = self._world.step(a_rl, self.tracker.monitor, self.shield)
        h = out.constraints
        info: StepInfo = {
            "constraints": {"o1": h[0], "o2": h[1]},
            "min_obstacle_distance": out.min_obstacle_distance,
            "collision": out.collision,
            "violation": out.violation,
            "action": out.action,
            "fsa_state": out.q,
            "success": out.accepted,
            "trap": out.trapped,
            "tl_reward": out.tl_reward,
        }
        if out.shield is not None:
            info["shield"] = shield_info(out.shield, a_rl)
        return out.observation, out.reward, out.terminated, out.truncated, info


def make_point_mass(config: str = FULL, evaluation: bool = False, **overrides: Any) -> gym.Env:
    """``gymnasium.make("tlshield/PointMass-v0", config=..., evaluation=..., **overrides)``.

    ``config`` picks the shield ("rl", "rl_cbf", "rl_clf", "rl_cbf_clf"); ``evaluation=True``
    turns the CBF on in every configuration. Any :class:`PointMassParams` field is a keyword
    override. See :class:`PointMassEnv` for the observation, reward and ``info``.
    """
    return PointMassEnv(config, evaluation, **overrides)
