"""The shielded envs ``tlshield/SafetyPointGoal1-v0``, ``Goal2-v0`` and ``SafetyCarGoal1-v0``.

This module owns :class:`SafetyGoalEnv` (Safety-Gymnasium's env, made through the adapter, with
the shield reading the privileged true state), its action spaces (:data:`ACTIONS`) and
:func:`make_safety_goal`, the entry point Gymnasium's registry calls.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from tlshield._core import Automaton, Monitor, Shield
from tlshield.envs.params import CONFIGS, FULL, build, check_config
from tlshield.envs.safety_gym.adapter import TASKS, make_builder
from tlshield.envs.safety_gym.lidar import BINS
from tlshield.envs.safety_gym.robots import CarModel, robot_of
from tlshield.envs.safety_gym.sensing import LidarState
from tlshield.envs.safety_gym.task import SafetyGoalParams, goal_spec
from tlshield.step_info import ShieldedStep

#: The policy's action spaces (``actions=``). ``"robot"`` (the default): each actuator's working
#: range as ``[-1, 1]`` (the Point's motor saturates at 0.05 of Safety-Gymnasium's box, the
#: Car's wheels at 0.02), so that a Gaussian policy's noise is noise in what the robot does.
#: ``"native"``: Safety-Gymnasium's own box, for rows like for like with the field's.
ACTIONS = ("robot", "native")
#: What the shield reads (``sensing=``). ``"state"`` (the default): MuJoCo's true positions of
#: the robot, the goal, the hazards and the vases. ``"lidar"``: only the agent's observation
#: (:mod:`~tlshield.envs.safety_gym.sensing`).
SENSING = ("state", "lidar")


class SafetyGoalEnv(gym.Env[NDArray[np.float64], NDArray[np.float64]]):
    """``tlshield/SafetyPointGoal1-v0`` and ``Goal2``: Safety-Gymnasium's env, shielded.

    Observation, action, reward and termination are Safety-Gymnasium's. ``info``: ``cost``
    (Safety-Gymnasium's ``cost_sum``), ``violation`` (cost > 0), ``goal_met``, ``shield`` (as
    in the bundled envs, with a shield) and ``state`` (the privileged state the shield
    read). ``config`` picks the shield's parts (``rl`` is Safety-Gymnasium unshielded);
    ``evaluation=True`` turns the CBF on in every configuration, as for every bundled env.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": []}

    def __init__(
        self,
        task: str = "SafetyPointGoal1-v0",
        config: str = FULL,
        evaluation: bool = False,
        actions: str = "robot",
        sensing: str = "state",
        **overrides: Any,
    ) -> None:
        check_config(config)
        if task not in TASKS:
            raise ValueError(f"task = {task!r}: the shielded envs are {', '.join(TASKS)}")
        if not isinstance(actions, str) or actions not in ACTIONS:
            raise ValueError(f"actions = {actions!r}: expected one of {', '.join(ACTIONS)}")
        if not isinstance(sensing, str) or sensing not in SENSING:
            raise ValueError(f"sensing = {sensing!r}: expected one of {', '.join(SENSING)}")
        self.robot = robot_of(task)
        self.params = build(SafetyGoalParams, {**self.robot.defaults, **overrides}, task)
        # What a copy is rebuilt from (see __getstate__).
        self._args = (task, config, evaluation, actions, sensing, dict(overrides))
        self._episode: tuple[int, list[NDArray[np.float64]]] | None = None
        self.config = config
        self.task = task
        self.actions = actions
        self.sensing = sensing
        self._env = make_builder(task)
        self.observation_space = self._env.observation_space
        native = self._env.action_space
        # Safety-Gymnasium's action per unit of the policy's (1 for its own box).
        self._scale = self.robot.scale if actions == "robot" else np.ones(2)
        if actions == "robot":
            hi = np.minimum(native.high / self._scale, 1.0)
            self.action_space = gym.spaces.Box(-hi, hi, dtype=native.dtype)
        else:
            self.action_space = native
        sg = self._env.task
        self._hazards = sg.hazards.num if hasattr(sg, "hazards") else 0
        vases = getattr(sg, "vases", None)
        self._vases = vases.num if vases is not None and vases.is_constrained else 0
        robot = self.robot
        self._sensing: LidarState | None = None
        slack = 0.0
        if sensing == "lidar":
            # One slot per lidar bin in place of one per object, and the barriers grown by
            # what the robot may move between readings.
            radii = {"hazards": 0.2 + self.params.hazard_margin}
            if self._vases:
                radii["vases"] = self.params.vase_radius
            self._sensing = LidarState(
                self.sensor,
                agent_dim=robot.agent_dim,
                ahead=robot.ahead,
                pivot=robot.pivot,
                radii=radii,
            )
            # One obstacle per bin, hazards' and vases' readings shared (their barrier
            # radius the hazards'), grown by what the robot may move between readings.
            self._hazards, self._vases = BINS, 0
            slack = self.params.lidar_slack
        self._state_dim = robot.agent_dim + 2 * (1 + self._hazards + self._vases)
        spec = goal_spec(
            self._hazards, self._vases, self.params, robot.agent_dim, robot.pivot, slack
        )
        self.automaton: Automaton = spec.automaton()
        use_cbf, use_clf = CONFIGS[config]
        use_cbf = use_cbf or evaluation
        self.shield = self._shield(use_cbf, use_clf)
        # With a routing CLF the reward's goal term reads the way the shield drives (see
        # `detour`), so the reward and the guidance pull the same way around obstacles.
        self.monitor = Monitor(self.automaton, routed_by=self.shield)
        #: Filter, advance the monitor, build ``info`` (:mod:`tlshield.step_info`).
        self._step = ShieldedStep(self.monitor)
        self._routed = self.shield is not None and self.shield.routes
        self._reward_distance = float(self._env.task.goal.reward_distance)
        self._detour = 0.0
        self._state: NDArray[np.float64] | None = None
        self._entries: dict[str, NDArray[np.intp]] | None = None

    def _shield(self, use_cbf: bool, use_clf: bool) -> Shield | None:
        if not (use_cbf or use_clf):
            return None
        p = self.params
        bounds = {0: p.position_error, 1: p.position_error, 2: p.heading_error}
        # The velocity's rate: vx, vy for the Point, the speed v for the Car.
        bounds |= {d: p.velocity_error for d in range(3, self.robot.agent_dim)}
        return Shield(
            self.automaton,
            self.robot.model(self._state_dim),
            alpha=p.alpha,
            alpha2=p.alpha2,
            c3=p.c3,
            k=p.k,
            clf_gain=p.clf_gain,
            cbf_bounds=(-2.0, 2.0),
            clf_bounds=(-p.clf_bound, p.clf_bound),
            action_bounds=self.robot.input_box(),
            rl_bounds=(-1.0, 1.0),
            margin=p.margin,
            route_clearance=p.route_clearance,
            # The Car's model is a user model: name the heading its turn steers, for routing.
            heading=2 if isinstance(self.robot, CarModel) else None,
            use_cbf=use_cbf,
            use_clf=use_clf,
            disturbance={d: w for d, w in bounds.items() if w > 0},
        )

    def _find_agent(self) -> None:
        # Safety-Gymnasium rebuilds the MuJoCo world on reset and when it places a new goal
        # (the agent's body then starts where it was, its joints at 0).
        model = self._env.task.model
        self._at = self.robot.locate(model)
        names = ["goal", *(f"hazard{i}" for i in range(self._hazards))]
        names += [f"vase{i}" for i in range(self._vases)]
        self._bodies = np.array([model.body(n).id for n in names])
        self._buffer = np.zeros(self._state_dim)

    def _read(self, obs: NDArray[np.float64]) -> NDArray[np.float64]:
        # What the shield reads: MuJoCo's state, or the observation alone.
        return self.true_state() if self._sensing is None else self._sensing.read(obs)

    def true_state(self) -> NDArray[np.float64]:
        """The privileged state: the agent's (Point: ``x, y, theta, vx, vy``; Car: ``x, y,
        psi, v``), then the goal's ``x, y``, the hazards' and the vases': the agent from
        MuJoCo's joints, the objects from their bodies' positions."""
        data = self._env.task.data
        s = self._buffer
        self.robot.read(data, self._at, s)
        s[self.robot.agent_dim :] = data.xpos[self._bodies, :2].ravel()
        return s.copy()

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float64], dict[str, Any]]:
        super().reset(seed=seed)
        if seed is None:  # Safety-Gymnasium draws its layout from its own seed
            seed = int(self.np_random.integers(2**31 - 1))
        return self._start(seed)

    def _start(self, seed: int) -> tuple[NDArray[np.float64], dict[str, Any]]:
        # An episode of Safety-Gymnasium's from its seed: with the actions since, all a copy
        # needs to continue it (MuJoCo and Safety-Gymnasium replay them exactly).
        obs, info = self._env.reset(seed=seed)
        self._episode = (seed, [])
        if self._sensing is None:
            self._find_agent()
        else:
            # The env's step, for the odometry: MuJoCo's timestep times the substeps (the
            # world exists once reset).
            sg = self._env.task
            self._sensing.reset(float(sg.model.opt.timestep) * sg.sim_conf.frameskip_binom_n)
        self._state = self._read(np.asarray(obs, dtype=np.float64))
        self.monitor.reset(self._state)
        self._detour = self.detour()
        return np.asarray(obs, dtype=np.float64), {**info, "state": self._state}

    def __getstate__(self) -> dict[str, Any]:
        """Copied and pickled as data: the constructor's arguments, the env's random stream,
        and the episode as its reset seed and the actions since (Safety-Gymnasium's MuJoCo
        world holds no state a pickle could carry; replaying the episode rebuilds it exactly,
        bit for bit, at a cost of one step per step taken)."""
        rng = None if self._np_random is None else self._np_random.bit_generator.state
        episode = None
        if self._episode is not None:
            seed, taken = self._episode
            episode = (seed, [a.tolist() for a in taken])
        return {"args": self._args, "rng": rng, "episode": episode}

    def __setstate__(self, state: dict[str, Any]) -> None:
        task, config, evaluation, actions, sensing, overrides = state["args"]
        self.__init__(task, config, evaluation, actions, sensing, **overrides)  # type: ignore[misc]
        if state["episode"] is not None:
            seed, taken = state["episode"]
            self._start(seed)
            for a in taken:
                self.step(np.asarray(a, dtype=np.float64))
        if state["rng"] is not None:
            bits = getattr(np.random, state["rng"]["bit_generator"])()
            bits.state = state["rng"]
            self._np_random = np.random.Generator(bits)

    def detour(self) -> float:
        """How much longer the way the shield's router drives to the goal is than the straight
        line, at the last state (m; 0 without a routing CLF, or with nothing in the way).

        Safety-Gymnasium pays ``reward_distance`` per metre the straight distance to the goal
        shrinks. Under a routing shield PPO learns from that reward plus ``reward_distance``
        per metre the detour shrinks: per metre of the routed way left, as the CLF drives. The
        extra term is a difference of potentials within each goal (restarted when a goal is
        met), so it moves no optimum; ``info["task_reward"]`` keeps Safety-Gymnasium's reward.
        """
        way, goal = self.monitor.goal_distance, self.monitor.goal
        if not self._routed or way is None or goal is None or self._state is None:
            return 0.0
        p = self._state
        return max(0.0, way - math.hypot(p[0] - goal[0], p[1] - goal[1]))

    @property
    def lidar_range(self) -> float:
        """The lidar's range (m): a bin reads ``1 - distance / range``."""
        return float(self._env.task.lidar_conf.max_dist)

    def sensor(self, obs: NDArray[np.float64], name: str) -> NDArray[np.float64]:
        """The values of one entry of the (flat) observation, e.g. ``"velocimeter"`` (the
        body-frame velocity) or ``"hazards_lidar"``."""
        if self._entries is None:
            space = self._env.task.obs_info.obs_space_dict
            marks = {k: np.full(v.shape, i, float) for i, (k, v) in enumerate(space.items())}
            flat = gym.spaces.utils.flatten(space, marks)
            self._entries = {k: np.flatnonzero(flat == i) for i, k in enumerate(space)}
        return np.asarray(obs)[self._entries[name]]

    def lidar(self, obs: NDArray[np.float64], name: str = "hazards") -> NDArray[np.float64]:
        """The bins of the observation's ``<name>_lidar`` (closeness in ``[0, 1]`` per
        direction: bin 0 starts at the agent body's +x axis and the bins run
        counter-clockwise; the Point's +x is its heading, the Car's heading is its -y,
        :attr:`CarModel.ahead`). :mod:`tlshield.envs.safety_gym.lidar` reads them."""
        return self.sensor(obs, f"{name}_lidar")

    def native_action(self, action: NDArray[np.float64]) -> NDArray[np.float64]:
        """An action of this env's space as Safety-Gymnasium's (``actions="robot"``: scaled by
        the robot's :attr:`~PointModel.scale`)."""
        return self._scale * np.asarray(action, dtype=np.float64)

    def shield_input(self, action: NDArray[np.float64]) -> NDArray[np.float64]:
        """An action of this env's space in the shield's units (:meth:`PointModel.shield_input`,
        :meth:`CarModel.shield_input`)."""
        return self.robot.shield_input(self.native_action(action))

    def _own(self, robot_action: NDArray[np.float64]) -> NDArray[np.float64]:
        # The robot's own action in this env's space.
        return robot_action if self.actions == "robot" else self.robot.scale * robot_action

    def env_action(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        """The action of this env's space for the shield's input ``u``."""
        return self._own(self.robot.actuators(u))

    def drive(self, thrust: float, turn: float) -> NDArray[np.float64]:
        """The action of this env's space for a push along the heading and a turn, each in
        ``[-1, 1]`` (:meth:`PointModel.drive`)."""
        return self._own(self.robot.drive(thrust, turn))

    def step(
        self, action: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], float, bool, bool, dict[str, Any]]:
        if self._state is None:
            raise RuntimeError("call reset() before step()")
        action = np.asarray(action, dtype=np.float64)
        if action.shape != (2,) or not (math.isfinite(action[0]) and math.isfinite(action[1])):
            raise ValueError(f"action: expected 2 finite values, got {action!r}")
        u_rl = self.shield_input(action)
        u, result = self._step.filter(self.shield, u_rl)
        # In this env's space; the shield's correction is what the penalty prices.
        applied = action if result is None else self.env_action(u)
        penalty = 0.0
        if result is not None:
            penalty = self.params.correction_penalty * float(np.linalg.norm(u - u_rl))
        assert self._episode is not None  # set with _state
        self._episode[1].append(action.copy())
        obs, reward, cost, terminated, truncated, info = self._env.step(self.native_action(applied))
        goal_met = bool(info.get("goal_met", False))
        if goal_met and self._sensing is None:
            self._find_agent()
        elif goal_met and self._sensing is not None:
            self._sensing.forget_goal()
        self._state = self._read(np.asarray(obs, dtype=np.float64))
        # A goal met: a new one was placed, and the task starts again.
        step = self._step.advance(self._state, restart=goal_met)
        detour = self.detour()
        shaping = 0.0 if goal_met else self._reward_distance * (self._detour - detour)
        self._detour = detour
        info = self._step.info(
            info,
            cost=float(cost),
            violation=float(cost) > 0.0,
            goal_met=goal_met,
            # What training's metrics count (as for every bundled env): a goal met is a
            # success, and the automaton's trap (inside a hazard's or a vase's disc) an entry.
            success=goal_met,
            trap=bool(step.trapped),
            task_reward=float(reward),
            detour=detour,
            action=applied,
            state=self._state,
        )
        return (
            np.asarray(obs, dtype=np.float64),
            float(reward) + shaping - penalty,
            terminated,
            truncated,
            info,
        )


def make_safety_goal(
    task: str,
    config: str = FULL,
    evaluation: bool = False,
    actions: str = "robot",
    sensing: str = "state",
    **overrides: Any,
) -> gym.Env:
    """``gymnasium.make("tlshield/SafetyPointGoal1-v0", config=..., evaluation=...,
    actions=..., sensing=..., ...)``."""
    return SafetyGoalEnv(task, config, evaluation, actions, sensing, **overrides)
