"""The paper's case study (Li & Belta, Sec. VI): a channel, three goals, two moving obstacles.

State (13 values): reference point ``x, y``, heading ``theta``, goal centres ``g1, g2, g3``
(x, y each) and obstacle centres ``o1, o2`` (x, y each). The action is ``(a_v, a_theta)`` of
the unicycle's reference point, normalised to ``[-1, 1]^2`` (scaled to
``ChannelParams.rl_bounds``; ``info["shield"]["a_rl"]`` is in physical units).

Observation (``ChannelParams.observation``): ``"relative"`` (default, 20 values + the one-hot
FSA state): ``cos theta, sin theta``, the two channel constraints ``c1, c2``, the goals and
the obstacles relative to the agent and the obstacles' velocities (measured from their last
two positions) and the automaton's next goal (Eq. 5B1, zero in acceptance), all in the
agent's frame (x ahead, y to the left); ``"paper"``: the 13 state values followed by the
one-hot FSA state.

Every constant of the environment is a field of :class:`ChannelParams` (documented there) and
can be overridden by keyword in ``gymnasium.make("tlshield/Channel-v0", ...)``.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from tlshield._core import ChannelWorld
from tlshield.copying import IndependentCopies
from tlshield.envs.channel_task import (
    CONFIGS,
    GOAL_GAP,
    OBSERVATIONS,
    PAPER_ENV,
    TASK,
    TASK_WITH_OBSTACLES,
    ChannelParams,
    channel_model,
    channel_shield,
    channel_task_spec,
    obstacle_barriers,
    task_spec,
)
from tlshield.envs.layout import GOAL_DIMS, RELATIVE_DIM, STATE_DIM, THETA, X, Y
from tlshield.envs.params import FULL, build, check_config, shielded_config
from tlshield.step_info import StepInfo, shield_info
from tlshield.tracking import FsaTracker

#: Length of the relative observation before the one-hot FSA state.
SQRT2 = math.sqrt(2.0)


class ChannelEnv(IndependentCopies, gym.Env[NDArray[np.float64], NDArray[np.float64]]):
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
    reference point, scaled to ``ChannelParams.rl_bounds`` (by default +-1 m/s and +-2 rad/s).
    With ``shield_in_env=False`` ``step`` takes the applied action in physical units instead.

    ## Observation Space

    ``ChannelParams.observation = "relative"`` (default): 20 values then the one-hot automaton
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
    :class:`ChannelParams` field is a keyword override, checked here (a ValueError names it)::

        gymnasium.make("tlshield/Channel-v0", config="rl_cbf", observation="paper")

    ## Info

    ``fsa_state``, ``success``, ``trap``, ``constraints`` (``c1``, ``c2``),
    ``min_obstacle_distance``, ``collision``, ``violation``; after a step also ``action`` (the
    applied action), ``tl_reward`` and, when a shield filtered the step, ``shield``
    (:class:`tlshield.step_info.ShieldInfo`); after a reset ``goal_outside_channel`` and
    ``clf_goal_outside``. Every key is declared in :class:`tlshield.step_info.StepInfo`.
    """

    #: The names of ``info["constraints"]`` (a batch builds ``info`` from these).
    CONSTRAINTS: ClassVar[tuple[str, str]] = ("c1", "c2")
    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array", "human"], "render_fps": 10}

    def __init__(
        self,
        config: str = FULL,
        evaluation: bool = False,
        render_mode: str | None = None,
        shield_in_env: bool = True,
        **overrides: Any,
    ) -> None:
        check_config(config)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode = {render_mode!r}: expected 'rgb_array', 'human' or None"
            )
        self.params = build(ChannelParams, overrides, "Channel-v0")
        self.config = config
        self.evaluation = evaluation
        self.render_mode = render_mode
        params = self.params
        self.spec_tl = task_spec(params)
        self._channel_atoms = (self.spec_tl.atoms.index("c1"), self.spec_tl.atoms.index("c2"))
        shield_config = shielded_config(config, evaluation)
        #: The plant; the shield is built on the same model.
        self.model = channel_model(params)
        self.shield = channel_shield(params, shield_config, self.spec_tl)
        self.shield_in_env = shield_in_env
        automaton = self.spec_tl.automaton()
        progress = None
        if params.task.reward == "progress":
            # The spec declares the goals exclusive (the draw keeps the discs apart), so one
            # state cannot count as reaching two goals: g3 is two transitions from the start.
            progress = automaton.progress_reward(
                gamma=params.task.gamma,
                horizon=params.task.horizon,
                scale=params.task.progress_scale,
                bonus=params.task.bonus,
                c_r=params.task.c_r,
                goal_weight=params.task.goal_weight,
                goal_span=params.task.goal_span,
            )
        # A routing shield's way around g3 is the goal term's distance (the reward and the
        # guidance agree).
        self.tracker = FsaTracker(
            automaton,
            params.task.c_r,
            params.trap_penalty,
            progress,
            routed_by=self.shield,
        )
        lo, hi = params.agent.arena
        margin = (
            max(params.task.outside_goal_v[1], max(params.obstacles.obstacle_amplitude))
            + params.task.goal_radius
        )
        k = automaton.num_states
        if params.observation.kind == "paper":
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
        # The policy acts in [-1, 1]^2 (what SB3 expects); the world scales it to the RL box
        # (rl_action).
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float64)
        #: The world the core steps: plant, obstacles, shield call, monitor, reward terms and
        #: observation in one call (this class draws the episodes and builds ``info``).
        self._world = ChannelWorld(
            self.model, params, evaluation=evaluation, channel_atoms=self._channel_atoms
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
        return ChannelWorld.xy(u, v)

    def _draw_goals(self) -> tuple[NDArray[np.float64], bool]:
        """g3 and one of g1/g2 inside the channel; the other outside with the configured
        probability. Returns the (3, 2) centres and whether one lies outside."""
        params, rng = self.params, self.np_random
        inside_v = params.task.half_width / SQRT2 - params.task.goal_radius
        outside = bool(rng.random() < params.task.outside_goal_probability)
        k = int(rng.integers(2))
        while True:
            us = rng.uniform(*params.task.near_goal_u, size=2)
            vs = rng.uniform(-inside_v, inside_v, size=2)
            if outside:
                vs[k] = rng.choice([-1.0, 1.0]) * rng.uniform(*params.task.outside_goal_v)
            near = np.array([self._xy(u, v) for u, v in zip(us, vs, strict=True)])
            if np.linalg.norm(near[0] - near[1]) >= 2 * params.task.goal_radius + GOAL_GAP:
                break
        far = self._xy(rng.uniform(*params.task.far_goal_u), rng.uniform(-inside_v, inside_v))
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
        a = np.asarray(action, dtype=np.float64)
        return self._world.rl_action(a.reshape(-1, 2)).reshape(a.shape)

    # --- Gymnasium API ------------------------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float64], dict[str, Any]]:
        super().reset(seed=seed)
        params, rng = self.params, self.np_random
        goals, outside = self._draw_goals()
        for i in range(2):
            self._obstacles[i] = (
                rng.uniform(*params.obstacles.obstacle_u),
                rng.uniform(*params.obstacles.obstacle_amplitude),
                rng.uniform(*params.obstacles.obstacle_frequency),
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
            rng.uniform(-params.agent.start_spread, params.agent.start_spread),
            rng.uniform(-params.agent.start_spread, params.agent.start_spread),
        )
        s[THETA] = math.pi / 4 + rng.uniform(
            -params.agent.start_heading, params.agent.start_heading
        )
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
            "clf_goal_outside": bool(
                goal is not None and abs(goal[1] - goal[0]) > params.task.half_width
            ),
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
        h = out.constraints
        info: StepInfo = {
            "fsa_state": out.q,
            "action": out.action,
            "success": out.accepted,
            "trap": out.trapped,
            "tl_reward": out.tl_reward,
            "constraints": {"c1": h[0], "c2": h[1]},
            "min_obstacle_distance": out.min_obstacle_distance,
            "collision": out.collision,
            "violation": out.violation,
        }
        if out.shield is not None:
            info["shield"] = shield_info(out.shield, out.a_rl)
        if self.render_mode == "human":
            self.render()
        return out.observation, out.reward, out.terminated, out.truncated, info

    def render(self) -> NDArray[np.uint8] | None:
        if self.render_mode is None:
            gym.logger.warn("render() without a render_mode; pass render_mode='rgb_array'")
            return None
        from tlshield.envs.render import ChannelRenderer, Scene

        if self._renderer is None:
            lo, hi = self.params.agent.arena
            scene = Scene(
                half_width=self.params.task.half_width,
                goal_radius=self.params.task.goal_radius,
                obstacle_radius=self.params.obstacles.obstacle_radius,
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

    def __getstate__(self) -> dict[str, Any]:
        # Copies and pickles hold the world, the monitor, the shield and the random stream as
        # data; the renderer's matplotlib figure is a view, rebuilt by the copy's next render.
        state = self.__dict__.copy()
        state["_renderer"] = None
        return state

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


__all__ = [
    "CONFIGS",
    "OBSERVATIONS",
    "PAPER_ENV",
    "RELATIVE_DIM",
    "TASK",
    "TASK_WITH_OBSTACLES",
    "ChannelEnv",
    "ChannelParams",
    "channel_model",
    "channel_shield",
    "channel_task_spec",
    "obstacle_barriers",
    "task_spec",
]
