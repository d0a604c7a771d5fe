"""``tlshield/PointMass-v0``: a double-integrator robot in a room with two round obstacles and
two goal regions; the task is to visit ``a``, then ``b``, without touching an obstacle before
``b`` (:data:`TASK`). Built as a user would build their own: a plain Gymnasium environment
of the physics (:class:`PointMassRoom`), wrapped by the public :class:`tlshield.FsaAugmented`
(task reward, automaton state) and :class:`tlshield.Shielded` (the shield), with the core's
:class:`tlshield.DoubleIntegrator` as both the plant and the shield's model. Under an
acceleration-level model a position constraint has relative degree 2, so the shield enforces
the obstacles with higher-order barriers (``alpha2``) and drives to the goals with the
second-order CLF (see the README's Semantics).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from tlshield._core import Ball, DoubleIntegrator, Shield, Spec
from tlshield.envs.params import build, renamed_class
from tlshield.wrappers import FsaAugmented, Shielded

#: Visit a, then b; stay out of both obstacles until b.
TASK = "F a & F b & (!b U a) & ((!o1 & !o2) U b)"

#: Which parts of the shield are on, per configuration (as for Channel-v0).
CONFIGS = {
    "rl": (False, False),
    "rl_cbf": (True, False),
    "rl_clf": (False, True),
    "rl_cbf_clf": (True, True),
}

#: The state: position ``x, y`` and velocity ``vx, vy``.
STATE_DIM = 4
POS, VEL = (0, 1), (2, 3)


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
        positive += ("c3", "k", "clf_gain", "clf_bound", "progress_scale", "margin")
        for name in positive:
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} = {getattr(self, name)!r}: expected a number > 0")
        if not (isinstance(self.horizon, int) and self.horizon > 0):
            raise ValueError(f"horizon = {self.horizon!r}: expected a positive integer")
        if not 0.0 < self.gamma <= 1.0:
            raise ValueError(f"gamma = {self.gamma!r}: expected a discount in (0, 1]")
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


def point_mass_spec(cfg: PointMassParams | None = None) -> Spec:
    """The task spec over the state ``[x, y, vx, vy]``."""
    cfg = cfg or PointMassParams()

    def disc(centre: tuple[float, float], radius: float) -> Ball:
        return Ball(pos=list(POS), radius=radius, center=list(centre))

    return Spec(
        TASK,
        {
            "a": disc(cfg.goal_a, cfg.goal_radius),
            "b": disc(cfg.goal_b, cfg.goal_radius),
            "o1": disc(cfg.obstacle_1, cfg.obstacle_radius),
            "o2": disc(cfg.obstacle_2, cfg.obstacle_radius),
        },
    )


def point_mass_shield(cfg: PointMassParams, config: str, spec: Spec) -> Shield | None:
    """The shield of a configuration (None for ``"rl"``): HOCBF rows for the obstacles and the
    goals' literals, the second-order CLF, the applied action kept in the acceleration box."""
    use_cbf, use_clf = CONFIGS[config]
    if not (use_cbf or use_clf):
        return None
    accel = cfg.max_accel
    return Shield(
        spec,
        DoubleIntegrator(pos=list(POS), vel=list(VEL)),
        alpha=cfg.alpha,
        alpha2=cfg.alpha2,
        c3=cfg.c3,
        k=cfg.k,
        cbf_bounds=(-2 * accel, 2 * accel),
        clf_bounds=(-cfg.clf_bound, cfg.clf_bound),
        action_bounds=(-accel, accel),
        rl_bounds=(-accel, accel),
        clf_gain=cfg.clf_gain,
        margin=cfg.margin,
        use_cbf=use_cbf,
        use_clf=use_clf,
    )


class PointMassRoom(gym.Env[NDArray[np.float64], NDArray[np.float64]]):
    """The physics alone: a 2-D double integrator in a room with two obstacles, no task.

    Observation: the state ``[x, y, vx, vy]``. Action: the acceleration ``(ax, ay)`` in
    m/s^2, clipped to ``[-max_accel, max_accel]``. Reward: ``-collision_penalty`` per step
    inside an obstacle, else 0 (the task reward comes from :class:`FsaAugmented`). Truncated at
    ``horizon`` steps; never terminated here (the task ends the episode on success). ``info``:
    ``collision``, ``violation`` (the same: inside an obstacle), ``min_obstacle_distance``
    (from the robot to the nearer obstacle's edge, negative inside) and ``constraints``
    (``{"o1": h, "o2": h}``, distance minus radius).
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": []}

    def __init__(self, cfg: PointMassParams) -> None:
        self.cfg = cfg
        self.model = DoubleIntegrator(pos=list(POS), vel=list(VEL))
        lo, hi = cfg.room
        span = hi - lo
        self.observation_space = gym.spaces.Box(
            np.array([lo, lo, -span, -span]), np.array([hi, hi, span, span]), dtype=np.float64
        )
        a = cfg.max_accel
        self.action_space = gym.spaces.Box(-a, a, shape=(2,), dtype=np.float64)
        self.state = np.zeros(STATE_DIM)
        self._t = 0

    def _measure(self) -> dict[str, Any]:
        cfg, p = self.cfg, self.state[list(POS)]
        h = {
            name: math.dist(p, centre) - cfg.obstacle_radius
            for name, centre in (("o1", cfg.obstacle_1), ("o2", cfg.obstacle_2))
        }
        inside = min(h.values()) < 0.0
        return {
            "constraints": h,
            "min_obstacle_distance": min(h.values()),
            "collision": inside,
            "violation": inside,
        }

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float64], dict[str, Any]]:
        super().reset(seed=seed)
        spread = self.cfg.start_spread
        p = np.asarray(self.cfg.start) + self.np_random.uniform(-spread, spread, size=2)
        self.state = np.array([p[0], p[1], 0.0, 0.0])
        self._t = 0
        return self.state.copy(), self._measure()

    def step(
        self, action: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], float, bool, bool, dict[str, Any]]:
        cfg = self.cfg
        a = np.asarray(action, dtype=np.float64).reshape(2)
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action {a} is not finite")
        a = np.clip(a, -cfg.max_accel, cfg.max_accel)
        nxt = np.asarray(self.model.step(self.state, a, cfg.dt))
        lo, hi = cfg.room
        for p, v in zip(POS, VEL, strict=True):
            if not lo <= nxt[p] <= hi:
                nxt[p] = min(max(nxt[p], lo), hi)
                nxt[v] = 0.0
        self.state = nxt
        self._t += 1
        info = {**self._measure(), "action": a}
        reward = -cfg.collision_penalty * float(info["collision"])
        return self.state.copy(), reward, False, self._t >= cfg.horizon, info


def make_point_mass(
    config: str = "rl_cbf_clf", evaluation: bool = False, **overrides: Any
) -> gym.Env:
    """``gymnasium.make("tlshield/PointMass-v0", config=..., evaluation=..., **overrides)``.

    ``config`` picks the shield ("rl", "rl_cbf", "rl_clf", "rl_cbf_clf"); ``evaluation=True``
    turns the CBF on in every configuration. Observation: ``[x, y, vx, vy]`` then the one-hot
    automaton state. Reward: the progress-aware task reward (finishing always out-earns
    dawdling) plus the room's collision penalty. Terminated when the task is done; truncated at
    the horizon. ``info`` adds ``fsa_state``, ``success``, ``trap``, ``tl_reward`` and, with a
    shield, ``shield``. Any :class:`PointMassParams` field is a keyword override.
    """
    if config not in CONFIGS:
        raise ValueError(f"config = {config!r}: expected one of {sorted(CONFIGS)}")
    cfg = build(PointMassParams, overrides, "PointMass-v0")
    spec = point_mass_spec(cfg)
    env: gym.Env = FsaAugmented(
        PointMassRoom(cfg),
        spec,
        w=1.0,
        gamma=cfg.gamma,
        horizon=cfg.horizon,
        scale=cfg.progress_scale,
        exclusive=[["a", "b", "o1", "o2"]],
    )
    shield_config = config
    if evaluation and not CONFIGS[config][0]:
        shield_config = "rl_cbf_clf" if CONFIGS[config][1] else "rl_cbf"
    shield = point_mass_shield(cfg, shield_config, spec)
    if shield is not None:
        env = Shielded(env, shield)
    return env


def __getattr__(name: str) -> Any:
    """The 0.1 names of this module's classes, with a DeprecationWarning."""
    return renamed_class(globals(), __name__, name)
