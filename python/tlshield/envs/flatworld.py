"""``tlshield/FlatWorld-v0``: the FlatWorld benchmark of DeepLTL (Jackermeier & Abate, ICLR
2025), rebuilt from its published description (``src/envs/flatworld/flatworld.py`` of
mathiasj33/deep-ltl), with any scTLTL formula over its seven colours as the task.

A point in ``[-2, 2]^2`` moves ``p += 0.08 * clip(u, -1, 1)`` per step; leaving the square ends
the episode as a failure. Nine coloured discs (:data:`CIRCLES`) overlap; a colour holds while the
point is strictly inside any disc of that colour, so ``red`` and ``green`` are unions of two
discs and ``red & magenta`` or ``green & blue & aqua`` are regions. Starts are uniform in the
square outside every disc; the horizon is 500 steps.

Built only from the library's generic parts: colours are :class:`tlshield.Ball` predicates (a
list of balls is their union), the plant and the shield's model are one
:class:`tlshield.SingleIntegrator`, and the task and shield come from
:class:`tlshield.wrappers.FsaAugmented` and :class:`tlshield.wrappers.Shielded`. Nothing here
depends on the formula: ``gymnasium.make("tlshield/FlatWorld-v0", formula=...)`` takes any
formula over the colours. Unlike DeepLTL (one policy for all formulas, no map, no model), a
tlshield agent is trained per formula and its shield knows the discs and the dynamics.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from tlshield._core import Ball, Halfspace, Inside, Shield, SingleIntegrator, Spec
from tlshield.copying import IndependentCopies
from tlshield.envs.params import CONFIGS, FULL, build, check_config, shielded_config
from tlshield.wrappers import FsaAugmented, Shielded

#: The discs as published: centre, radius, colour.
CIRCLES: tuple[tuple[tuple[float, float], float, str], ...] = (
    ((-1.4, 0.55), 0.4, "red"),
    ((-1.1, 1.1), 0.5, "magenta"),
    ((-1.0, -1.2), 0.3, "yellow"),
    ((-1.53, -0.5), 0.32, "orange"),
    ((0.1, 0.0), 0.8, "blue"),
    ((0.5, -1.3), 0.35, "red"),
    ((0.7, 0.7), 0.5, "green"),
    ((1.5, -0.75), 0.4, "green"),
    ((0.8, 0.2), 0.3, "aqua"),
)

#: The colours, in order of first appearance in :data:`CIRCLES`.
COLOURS: tuple[str, ...] = tuple(dict.fromkeys(c for _, _, c in CIRCLES))

#: DeepLTL's five evaluation formulas for FlatWorld, exactly as published (``&``, ``|``, ``!``,
#: ``=>``, ``U``, ``F``). The first is the environment's default task.
FORMULAS: tuple[str, ...] = (
    "F((red & magenta) & F((blue & green) & F yellow))",
    "F(orange & (!red U magenta))",
    "(!red U (green & blue & aqua)) & F(orange & F(red & magenta))",
    "((!yellow & !orange) U (green & blue)) & (!green U magenta)",
    "(blue => F magenta) U (yellow | ((green & blue) & F orange))",
)


#: The state is the position ``x, y``.
POS = (0, 1)


@dataclass(frozen=True)
class FlatWorldParams:
    """Every constant of ``tlshield/FlatWorld-v0`` (each a keyword override of ``make``)."""

    # --- world (as published) ----------------------------------------------------------------
    #: Half-width of the square ``[-size, size]^2``; leaving it ends the episode as a failure.
    size: float = 2.0
    #: Displacement per step at full action.
    step_size: float = 0.08
    #: Episode length (steps).
    horizon: int = 500

    # --- reward ------------------------------------------------------------------------------
    #: The progress reward's discount (the trainer's gamma) and Eq. 5A1 scale.
    gamma: float = 0.99
    progress_scale: float = 1.0

    # --- shield --------------------------------------------------------------------------------
    #: CBF gain: ``alpha * step_size <= 1`` keeps the convex barriers (outside a disc, the walls)
    #: exact for the Euler plant.
    alpha: float = 5.0
    c3: float = 1.0
    #: CLF relaxation cost (the paper's K; see docs/concepts/shield.md on it and the CLF box).
    k: float = 1.0
    #: Box on a_clf, per axis.
    clf_bound: float = 0.5
    #: Barriers are kept this far above 0, for the Euler plant inside concave regions.
    margin: float = 0.02
    #: Keep out of guards that set the task back, not only the trap's (the shield's default).
    preserve_progress: bool = True

    def check(self) -> None:
        """Raises ValueError naming the first bad constant."""
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ValueError(f"{f.name} = {value!r}: expected a finite number")
        for name in ("size", "step_size", "alpha", "c3", "k", "clf_bound", "margin"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} = {getattr(self, name)!r}: expected a number > 0")
        if self.progress_scale <= 0:
            raise ValueError(f"progress_scale = {self.progress_scale!r}: expected a number > 0")
        if not (isinstance(self.horizon, int) and self.horizon > 0):
            raise ValueError(f"horizon = {self.horizon!r}: expected a positive integer")
        if not 0.0 < self.gamma <= 1.0:
            raise ValueError(f"gamma = {self.gamma!r}: expected a discount in (0, 1]")


def colour_predicates() -> dict[str, Ball | list[Ball]]:
    """Each colour's region: one :class:`tlshield.Ball`, or a list of them (their union)."""
    out: dict[str, list[Ball]] = {}
    for centre, radius, colour in CIRCLES:
        out.setdefault(colour, []).append(Ball(pos=list(POS), radius=radius, center=list(centre)))
    return {c: balls[0] if len(balls) == 1 else balls for c, balls in out.items()}


def flatworld_spec(formula: str) -> Spec:
    """The task spec of ``formula`` over the colours (an unknown colour is an error)."""
    return Spec(formula, colour_predicates())


def wall_barriers(size: float) -> dict[str, Inside]:
    """The square's four walls as barriers ``x < size`` etc. (the shield keeps the point in)."""
    return {
        "x<size": Inside(Halfspace([-1.0, 0.0], size)),
        "x>-size": Inside(Halfspace([1.0, 0.0], size)),
        "y<size": Inside(Halfspace([0.0, -1.0], size)),
        "y>-size": Inside(Halfspace([0.0, 1.0], size)),
    }


def flatworld_shield(params: FlatWorldParams, config: str, spec: Spec) -> Shield | None:
    """The shield of a configuration (None for ``"rl"``): the safe set and the walls as
    barriers, the CLF towards the next region, the applied action in ``[-1, 1]^2``."""
    use_cbf, use_clf = CONFIGS[config]
    if not (use_cbf or use_clf):
        return None
    return Shield(
        spec,
        SingleIntegrator(pos=list(POS)),
        alpha=params.alpha,
        c3=params.c3,
        k=params.k,
        cbf_bounds=(-2.0, 2.0),
        clf_bounds=(-params.clf_bound, params.clf_bound),
        action_bounds=(-1.0, 1.0),
        rl_bounds=(-1.0, 1.0),
        barriers=wall_barriers(params.size),
        margin=params.margin,
        dt=params.step_size,
        use_cbf=use_cbf,
        use_clf=use_clf,
        preserve_progress=bool(params.preserve_progress),
    )


class FlatWorld(IndependentCopies, gym.Env[NDArray[np.float64], NDArray[np.float64]]):
    """The physics alone: a point in a square with coloured discs, no task.

    Observation: the position ``[x, y]``. Action: ``u`` in ``[-1, 1]^2`` (clipped); each step
    moves ``step_size * u``. Reward 0 (the task reward comes from :class:`FsaAugmented`).
    Terminated on leaving the square (``info["box_exit"]``); truncated at ``horizon``.
    ``info`` also has ``violation`` and ``collision`` (both: left the square),
    ``constraints`` (the walls' ``h``) and ``min_obstacle_distance`` (to the nearest wall).
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(
        self, params: FlatWorldParams | None = None, render_mode: str | None = None
    ) -> None:
        self.params = params or FlatWorldParams()
        self.model = SingleIntegrator(pos=list(POS))
        # The farthest a step can leave the square: the last observation of an exit.
        s = self.params.size + self.params.step_size * math.sqrt(2.0)
        self.observation_space = gym.spaces.Box(-s, s, shape=(2,), dtype=np.float64)
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float64)
        self.render_mode = render_mode
        self.state = np.zeros(2)
        self.path: list[NDArray[np.float64]] = []
        self._t = 0

    def _measure(self, exited: bool) -> dict[str, Any]:
        s, (x, y) = self.params.size, self.state
        h = {"x<size": s - x, "x>-size": x + s, "y<size": s - y, "y>-size": y + s}
        return {
            "constraints": h,
            "min_obstacle_distance": min(h.values()),
            "box_exit": exited,
            "violation": exited,
            "collision": exited,
        }

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float64], dict[str, Any]]:
        super().reset(seed=seed)
        s = self.params.size
        while True:  # uniform in the square, outside every disc (rejection sampling)
            p = self.np_random.uniform(-s, s, size=2)
            if all(math.dist(p, c) >= r for c, r, _ in CIRCLES):
                break
        self.state = p
        self.path = [p.copy()]
        self._t = 0
        return self.state.copy(), self._measure(False)

    def step(
        self, action: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], float, bool, bool, dict[str, Any]]:
        a = np.asarray(action, dtype=np.float64).reshape(2)
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action {a} is not finite")
        self.state = np.asarray(
            self.model.step(self.state, np.clip(a, -1.0, 1.0), self.params.step_size)
        )
        self.path.append(self.state.copy())
        self._t += 1
        exited = bool(np.any(np.abs(self.state) > self.params.size))
        info = {**self._measure(exited), "action": a}
        return self.state.copy(), 0.0, exited, self._t >= self.params.horizon, info

    def render(self) -> NDArray[np.uint8] | None:
        if self.render_mode != "rgb_array":
            return None
        from tlshield.envs.flatworld_map import draw_paths

        return draw_paths([np.asarray(self.path)], CIRCLES, size=self.params.size)


def make_flatworld(
    formula: str = FORMULAS[0],
    config: str = FULL,
    evaluation: bool = False,
    render_mode: str | None = None,
    **overrides: Any,
) -> gym.Env:
    """``gymnasium.make("tlshield/FlatWorld-v0", formula=..., config=..., **overrides)``.

    ``formula``: any scTLTL formula over :data:`COLOURS`. ``config`` picks the shield ("rl",
    "rl_cbf", "rl_clf", "rl_cbf_clf"); ``evaluation=True`` turns the CBF on in every
    configuration. Observation: ``[x, y]`` then the one-hot automaton state. Reward: the
    progress-aware task reward. Terminated on success, on entering the trap (the formula is
    violated) and on leaving the square (both failures, paying the trap penalty); truncated at
    the horizon. Any :class:`FlatWorldParams` field is a keyword override.
    """
    check_config(config)
    params = build(FlatWorldParams, overrides, "FlatWorld-v0")
    spec = flatworld_spec(formula)
    env: gym.Env = FsaAugmented(
        FlatWorld(params, render_mode=render_mode),
        spec,
        gamma=params.gamma,
        horizon=params.horizon,
        scale=params.progress_scale,
        terminate_on_trap=True,
        failure_on_termination=True,
    )
    shield_config = shielded_config(config, evaluation)
    shield = flatworld_shield(params, shield_config, spec)
    if shield is not None:
        env = Shielded(env, shield)
    return env
