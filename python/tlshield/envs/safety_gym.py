"""Safety-Gymnasium's navigation tasks (PKU-Alignment), adapted to tlshield's stack and shielded.

**The adapter.** safety-gymnasium 1.0.0 as published does not import with gymnasium 1.x and
Python 3.11: its package ``__init__`` imports ``gymnasium.wrappers.compatibility`` (removed in
gymnasium 1.0), and its colours are numpy arrays used as dataclass defaults (refused since
Python 3.11: unhashable), and its Car robot reads a joint by the id a sensor's view gives, a
one-element numpy array, which MuJoCo 2.3.7's ``MjModel.jnt`` refuses under numpy 2.
:func:`load_builder` checks the installed versions (:data:`VERSIONS`), makes the package
importable without running its ``__init__`` (a module shell whose ``__path__`` is the
package's folder), makes the colour arrays hashable (a view with identity hashing; the values
are untouched), lets ``MjModel.jnt`` take a one-element integer array as the integer it holds
(every other argument goes through as it is), and returns its ``Builder``, the env class
every Safety-Gymnasium task is made from. Nothing else is patched. ``make safety-gym``
installs the stack (docs/guides/safety-gym.md says what and why).

**The shielded envs** ``tlshield/SafetyPointGoal1-v0`` and ``tlshield/SafetyPointGoal2-v0``
(:class:`SafetyGoalEnv`) keep Safety-Gymnasium's observation, action, reward and cost
(``info["cost"]``); the shield reads the **privileged true state** (the agent's pose and
velocity from MuJoCo, the goal, hazards and vases), which the policy never sees:

* the robot: :class:`tlshield.ThrustTurn`, identified from MuJoCo (:data:`POINT`), with the
  measured one-step error as the shield's ``disturbance`` bounds;
* the task: ``(!h1 & ... & !hN & !v1 & ...) U goal``, hazards (and Goal2's vases) in the
  formula: its safe set keeps them out, and its CLF drives to the goal. When the goal is met
  Safety-Gymnasium places a new one and the task starts again.
"""

from __future__ import annotations

import functools
import importlib.metadata
import importlib.util
import math
import os
import sys
import types
import warnings
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from tlshield._core import Automaton, Ball, ControlAffine, Monitor, Shield, Spec, ThrustTurn
from tlshield.envs.params import CONFIGS, FULL, build, check_config
from tlshield.tracking import shield_info

#: The versions the adapter was written and tested against (it patches exactly these).
VERSIONS = {"safety-gymnasium": "1.0.0", "mujoco": "2.3.7"}
#: What installs them.
INSTALL = (
    "make safety-gym (or: pip install --no-deps safety-gymnasium==1.0.0 && pip install "
    "mujoco==2.3.7 xmltodict pyyaml imageio)"
)
#: The tasks registered as ``tlshield/<task>``.
TASKS = ("SafetyPointGoal1-v0", "SafetyPointGoal2-v0", "SafetyCarGoal1-v0")
#: The tasks :func:`make_builder` makes (Safety-Gymnasium's own, unshielded).
BUILDER_TASKS = TASKS
#: The policy's action spaces (``actions=``). ``"robot"`` (the default): each actuator's working
#: range as ``[-1, 1]`` (the Point's motor saturates at 0.05 of Safety-Gymnasium's box, the
#: Car's wheels at 0.02), so that a Gaussian policy's noise is noise in what the robot does.
#: ``"native"``: Safety-Gymnasium's own box, for rows like for like with the field's.
ACTIONS = ("robot", "native")


class MissingStack(ImportError):
    """The Safety-Gymnasium stack is missing or at another version than :data:`VERSIONS`."""


def installed() -> bool:
    """Whether the Safety-Gymnasium stack of :data:`VERSIONS` is installed."""
    try:
        return all(importlib.metadata.version(p) == v for p, v in VERSIONS.items())
    except importlib.metadata.PackageNotFoundError:
        return False


class _HashableArray(np.ndarray):
    """A colour array that dataclasses accept as a default (identity hash, values as given)."""

    __hash__ = object.__hash__  # type: ignore[assignment]


@functools.cache
def load_builder() -> type:
    """Safety-Gymnasium's ``Builder`` after the adapter's checks and patches (see the module
    docs); :class:`MissingStack` (an ImportError) saying what to install when the stack is
    missing or at another version."""
    for package, wanted in VERSIONS.items():
        try:
            got = importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            raise MissingStack(f"{package} is not installed; install it with {INSTALL}") from None
        if got != wanted:
            raise MissingStack(
                f"{package} {got} is installed, but the adapter patches {package} {wanted}; "
                f"install it with {INSTALL}"
            )
    if "safety_gymnasium" not in sys.modules:
        spec = importlib.util.find_spec("safety_gymnasium")
        assert spec is not None and spec.submodule_search_locations is not None
        root = next(iter(spec.submodule_search_locations))
        shell = types.ModuleType("safety_gymnasium")
        shell.__path__ = [root]
        shell.__file__ = os.path.join(root, "__init__.py")
        sys.modules["safety_gymnasium"] = shell
        from safety_gymnasium.assets import color  # type: ignore[import-not-found]

        for name, value in list(color.COLOR.items()):
            color.COLOR[name] = np.asarray(value).view(_HashableArray)
    _accept_array_joint_ids()
    from safety_gymnasium.builder import Builder  # type: ignore[import-not-found]

    return Builder


def _accept_array_joint_ids() -> None:
    """``MjModel.jnt(id)`` with ``id`` a one-element integer array (a sensor view's
    ``objid``) reads joint ``int(id)``; any other argument is passed on untouched."""
    import mujoco

    jnt = mujoco.MjModel.jnt
    if getattr(jnt, "_tlshield_patched", False):
        return

    def patched(self: Any, *args: Any, **kwargs: Any) -> Any:
        if len(args) == 1 and not kwargs:
            key = args[0]
            if isinstance(key, np.ndarray) and key.size == 1 and key.dtype.kind in "iu":
                args = (int(key.reshape(())),)
        return jnt(self, *args, **kwargs)

    patched._tlshield_patched = True  # type: ignore[attr-defined]
    mujoco.MjModel.jnt = patched


def make_builder(task: str) -> Any:
    """Safety-Gymnasium's own env of ``task`` (one of :data:`BUILDER_TASKS`, e.g.
    ``"SafetyPointGoal1-v0"``), through the adapter. Its ``step`` returns Safety-Gymnasium's
    6-tuple."""
    if task not in BUILDER_TASKS:
        raise ValueError(f"task = {task!r}: the adapter supports {', '.join(BUILDER_TASKS)}")
    robot = task.removeprefix("Safety").split("Goal")[0]
    builder = load_builder()
    with warnings.catch_warnings():
        # Safety-Gymnasium builds its action Box from MuJoCo's float32 control range as
        # float64, and Gymnasium's check casts float64's limits to float32 on the way: a
        # harmless overflow warning at every make, about no value of the space.
        warnings.filterwarnings("ignore", "overflow encountered in cast", RuntimeWarning)
        return builder(task, config={"agent_name": robot})


@dataclass(frozen=True)
class PointModel:
    """The Point robot as :class:`tlshield.ThrustTurn`, identified from MuJoCo.

    The first action is the motor's control: MuJoCo clips the motor's force at ``±0.05``
    (``forcerange``) before its gear of 0.3, so the thrust saturates at ``|a0| = 0.05``;
    the shield's first input is that saturated thrust scaled to ``[-1, 1]``
    (``u0 = clip(a0 / 0.05, -1, 1)``), and ``a0 = 0.05 u0`` is what is sent back. The second
    action commands the turn rate (a velocity actuator). The gains are least-squares fits of
    ``(v_{t+1} - v_t) / dt`` and of the heading's rate over random rollouts
    (``scripts/safety_gym_model.py`` measures them and the one-step error)."""

    #: Acceleration at full thrust (m/s^2), turn rate per unit of a1 (rad/s), drag (1/s).
    thrust: float = 2.846
    turn: float = 2.896
    drag: float = 1.915
    #: The control at which the motor's force saturates.
    saturation: float = 0.05
    #: The agent's part of the shield's state: ``x, y, theta, vx, vy``.
    agent_dim: ClassVar[int] = 5
    #: The robot's own defaults of :class:`SafetyGoalParams`: none, the class's are the
    #: Point's.
    defaults: ClassVar[dict[str, float]] = {}
    #: The cost is measured at the state's ``x, y`` (no point of the body ahead of it).
    pivot: ClassVar[float] = 0.0

    @property
    def scale(self) -> NDArray[np.float64]:
        """Safety-Gymnasium's action per unit of the robot's own (the motor's ``saturation``,
        the turn's 1)."""
        return np.array([self.saturation, 1.0])

    def model(self, state_dim: int = 5) -> ThrustTurn:
        """The core model over ``[x, y, theta, vx, vy, ...]``."""
        return ThrustTurn(self.thrust, self.turn, self.drag)

    def input_box(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """The shield's action box ``(lo, hi)`` per input (thrust, turn)."""
        return (-1.0, -1.0), (1.0, 1.0)

    def shield_input(self, action: NDArray[np.float64]) -> NDArray[np.float64]:
        """The policy's action in the shield's units: the motor's control scaled to its
        saturation and clipped, the turn as it is."""
        a0 = min(max(float(action[0]) / self.saturation, -1.0), 1.0)
        return np.array([a0, min(max(float(action[1]), -1.0), 1.0)])

    def actuators(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        """The robot's own action (each actuator's working range as ``[-1, 1]``) for the
        shield's input ``u``: the same two numbers."""
        return np.array([u[0], u[1]], dtype=np.float64)

    def env_action(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        """What Safety-Gymnasium is sent for the shield's input ``u``."""
        return self.scale * self.actuators(u)

    def drive(self, thrust: float, turn: float) -> NDArray[np.float64]:
        """The robot's own action (``actions="robot"``) for a push along the heading and a
        turn, each in ``[-1, 1]``."""
        return self.actuators(np.array([thrust, turn]))

    def locate(self, model: Any) -> Any:
        """Where the agent's pose and velocity are in MuJoCo's arrays (re-read whenever
        Safety-Gymnasium rebuilds the world): its slide joints move along the body's axes as
        placed, rotated by its initial yaw."""
        body = model.body("agent")
        w, _, _, z = body.quat  # a rotation about the vertical axis
        yaw0 = 2.0 * math.atan2(z, w)
        return types.SimpleNamespace(
            base=body.pos.copy(),
            yaw0=yaw0,
            rot0=(math.cos(yaw0), math.sin(yaw0)),
            qpos=[int(model.joint(n).qposadr[0]) for n in "xyz"],
            qvel=[int(model.joint(n).dofadr[0]) for n in "xyz"],
        )

    def read(self, data: Any, at: Any, s: NDArray[np.float64]) -> None:
        """Writes ``x, y, theta, vx, vy`` into ``s[:5]``."""
        qpos, qvel = data.qpos, data.qvel
        (x, y, z), (dx, dy, _) = at.qpos, at.qvel
        c, sn = at.rot0
        s[0] = at.base[0] + c * qpos[x] - sn * qpos[y]
        s[1] = at.base[1] + sn * qpos[x] + c * qpos[y]
        s[2] = at.yaw0 + qpos[z]
        s[3] = c * qvel[dx] - sn * qvel[dy]
        s[4] = sn * qvel[dx] + c * qvel[dy]

    def forward_speed(self, velocimeter: NDArray[np.float64]) -> float:
        """The speed along the heading, from the velocimeter (body frame, ``x`` ahead)."""
        return float(velocimeter[0])

    #: The heading's angle in the body frame the lidars and sensors read (``x`` ahead).
    ahead: ClassVar[float] = 0.0


#: The Point robot's identified model.
POINT = PointModel()


@dataclass(frozen=True)
class CarModel:
    """The Car robot, a differential drive on a free joint, as a
    :class:`tlshield.ControlAffine` model identified from MuJoCo
    (``scripts/safety_gym_car_model.py``).

    State ``x, y, psi, v``: the centre, the heading it drives along when both wheels push
    forward (the body's ``-y`` axis, measured) and the speed along it. The wheel motors
    saturate at ``|a| = 0.02``; with ``uL, uR = clip(a / 0.02, -1, 1)`` the shield's inputs
    are ``u0 = (uL + uR) / 2`` (drive) and ``u1 = (uL - uR) / 2`` (turn):

    ``dx = v cos psi,  dy = v sin psi,  dpsi = turn u1,  dv = push u0 - drag v``.

    The speed's lag is fitted (Safety-Gymnasium's step is 0.04 s for the Car); the yaw rate's
    lag (about 0.05 s) is not modelled: the turn is a rate. A wheel command is ``u0 ± u1``, so
    the inputs the wheels can follow are the diamond ``|u0| + |u1| <= 1``; the shield's box is
    inside it (``|u0| <= share``, ``|u1| <= 1 - share``), so that what it sends is what the
    wheels do."""

    #: dv/dt per unit of u0 (m/s^2), the speed's decay (1/s), dpsi/dt per unit of u1 (rad/s).
    push: float = 3.886
    drag: float = 6.253
    turn: float = 1.442
    #: The wheel motors' saturation.
    saturation: float = 0.02
    #: The drive's share of the wheels' range (the turn gets the rest).
    share: float = 0.5
    #: How far the body's origin (where Safety-Gymnasium measures the cost and the goal) is
    #: ahead of the point that moves along the heading (m; the origin's sideways speed is
    #: this times the yaw rate, fitted). The state's ``x, y`` is that point; the barriers hold
    #: the origin, a point of the body (``Ball(..., heading=2, offset=(pivot, 0))``).
    pivot: float = 0.043
    #: The agent's part of the shield's state: ``x, y, psi, v``.
    agent_dim: ClassVar[int] = 4
    #: The Car's own defaults of :class:`SafetyGoalParams` (the rest, ``clf_bound = 1``
    #: among them, are the Point's). The Point's fast CLF decay and wide routes made the
    #: shield alone meet 1.5-2.2 goals per episode with the Car on the tuning seeds, against
    #: 5.5 with these (docs/guides/safety-gym.md, "The defaults").
    defaults: ClassVar[dict[str, float]] = {
        "alpha": 1.0,
        "alpha2": 2.0,
        "c3": 1.0,
        "clf_gain": 1.0,
        "route_clearance": 0.2,
    }

    @property
    def scale(self) -> NDArray[np.float64]:
        """Safety-Gymnasium's action per unit of the robot's own (each wheel's
        ``saturation``)."""
        return np.array([self.saturation, self.saturation])

    def model(self, state_dim: int) -> ControlAffine:
        """The core model over ``[x, y, psi, v, ...]`` (``state_dim`` values, the rest fixed:
        the goal's and the obstacles' centres)."""
        n = state_dim
        g = np.zeros((n, 2))
        g[3, 0], g[2, 1] = self.push, self.turn

        def f(s: NDArray[np.float64]) -> NDArray[np.float64]:
            out = np.zeros(n)
            out[0], out[1] = s[3] * math.cos(s[2]), s[3] * math.sin(s[2])
            out[3] = -self.drag * s[3]
            return out

        def jacobian(s: NDArray[np.float64]) -> NDArray[np.float64]:
            out = np.zeros((n, n))
            c, sn = math.cos(s[2]), math.sin(s[2])
            out[0, 2], out[0, 3] = -s[3] * sn, c
            out[1, 2], out[1, 3] = s[3] * c, sn
            out[3, 3] = -self.drag
            return out

        return ControlAffine(f, g, state_dim=n, inputs=2, jacobian=jacobian)

    def input_box(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """The shield's action box ``(lo, hi)`` per input (drive, turn)."""
        return (-self.share, self.share - 1.0), (self.share, 1.0 - self.share)

    def shield_input(self, action: NDArray[np.float64]) -> NDArray[np.float64]:
        """The policy's wheel commands in the shield's units (drive and turn, in the diamond
        ``|u0| + |u1| <= 1``)."""
        left = min(max(float(action[0]) / self.saturation, -1.0), 1.0)
        right = min(max(float(action[1]) / self.saturation, -1.0), 1.0)
        return np.array([(left + right) / 2.0, (left - right) / 2.0])

    def actuators(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        """The robot's own action, the wheels' commands in ``[-1, 1]`` of their working
        range, for the shield's input ``u``."""
        return np.array([u[0] + u[1], u[0] - u[1]], dtype=np.float64)

    def env_action(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        """The wheel commands Safety-Gymnasium is sent for the shield's input ``u``."""
        return self.scale * self.actuators(u)

    def drive(self, thrust: float, turn: float) -> NDArray[np.float64]:
        """The robot's own action (``actions="robot"``) for a push along the heading and a
        turn, each in ``[-1, 1]`` (scaled into the wheels' diamond; a positive turn is
        counter-clockwise)."""
        scale = 1.0 / max(1.0, abs(thrust) + abs(turn))
        return self.actuators(np.array([thrust * scale, turn * scale]))

    def locate(self, model: Any) -> Any:
        """Where the agent's free joint is in MuJoCo's arrays."""
        joint = model.joint("agent")
        return types.SimpleNamespace(q=int(joint.qposadr[0]), dq=int(joint.dofadr[0]))

    def read(self, data: Any, at: Any, s: NDArray[np.float64]) -> None:
        """Writes ``x, y, psi, v`` into ``s[:4]`` (the free joint's position less ``pivot``
        along ``psi``, its quaternion's yaw less a quarter turn, and its world velocity along
        ``psi``)."""
        qw, qx, qy, qz = data.qpos[at.q + 3 : at.q + 7]
        psi = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz)) - math.pi / 2
        c, sn = math.cos(psi), math.sin(psi)
        s[0] = data.qpos[at.q] - self.pivot * c
        s[1] = data.qpos[at.q + 1] - self.pivot * sn
        s[2] = psi
        s[3] = data.qvel[at.dq] * c + data.qvel[at.dq + 1] * sn

    def forward_speed(self, velocimeter: NDArray[np.float64]) -> float:
        """The speed along the heading, from the velocimeter (body frame, ``-y`` ahead)."""
        return -float(velocimeter[1])

    #: The heading's angle in the body frame the lidars and sensors read (``-y`` ahead).
    ahead: ClassVar[float] = -math.pi / 2.0


#: The Car robot's identified model.
CAR = CarModel()
#: The shielded robots by Safety-Gymnasium's name.
ROBOTS: dict[str, PointModel | CarModel] = {"Point": POINT, "Car": CAR}


def robot_of(task: str) -> PointModel | CarModel:
    """The robot model of a task (``"SafetyCarGoal1-v0"``: :data:`CAR`)."""
    return ROBOTS[task.removeprefix("Safety").split("Goal")[0]]


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

    #: The settings that may be 0 (every other one must be > 0).
    _MAY_BE_ZERO: ClassVar[tuple[str, ...]] = (
        "position_error",
        "velocity_error",
        "heading_error",
        "correction_penalty",
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
    hazards: int, vases: int, params: SafetyGoalParams, agent_dim: int = 5, pivot: float = 0.0
) -> Spec:
    """``(!h1 & ... & !v1 & ...) U goal`` over the shield's state: the agent's ``agent_dim``
    values, the goal's ``x, y``, then two values per hazard and per vase (the objects' centres
    are read from the state, so one spec serves every layout). With ``pivot`` > 0 the hazards
    and vases hold the point ``pivot`` ahead of ``x, y`` along the heading ``s[2]``."""
    # The goal is 0.3 m in Safety-Gymnasium; 0.25 here, so that Safety-Gymnasium meets it (and
    # places the next one, which restarts the task) before the automaton accepts.
    goal = [agent_dim, agent_dim + 1]
    preds: dict[str, Ball] = {"goal": Ball(pos=[0, 1], radius=0.25, center_dims=goal)}
    radius = {"h": 0.2 + params.hazard_margin, "v": params.vase_radius}
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
        **overrides: Any,
    ) -> None:
        check_config(config)
        if task not in TASKS:
            raise ValueError(f"task = {task!r}: the shielded envs are {', '.join(TASKS)}")
        if not isinstance(actions, str) or actions not in ACTIONS:
            raise ValueError(f"actions = {actions!r}: expected one of {', '.join(ACTIONS)}")
        self.robot = robot_of(task)
        self.params = build(SafetyGoalParams, {**self.robot.defaults, **overrides}, task)
        # What a copy is rebuilt from (see __getstate__).
        self._args = (task, config, evaluation, actions, dict(overrides))
        self._episode: tuple[int, list[NDArray[np.float64]]] | None = None
        self.config = config
        self.task = task
        self.actions = actions
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
        self._state_dim = self.robot.agent_dim + 2 * (1 + self._hazards + self._vases)
        robot = self.robot
        spec = goal_spec(self._hazards, self._vases, self.params, robot.agent_dim, robot.pivot)
        self.automaton: Automaton = spec.automaton()
        use_cbf, use_clf = CONFIGS[config]
        use_cbf = use_cbf or evaluation
        self.shield = self._shield(use_cbf, use_clf)
        # With a routing CLF the reward's goal term reads the way the shield drives (see
        # `detour`), so the reward and the guidance pull the same way around obstacles.
        self.monitor = Monitor(self.automaton, routed_by=self.shield)
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
        self._find_agent()
        self._state = self.true_state()
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
        task, config, evaluation, actions, overrides = state["args"]
        self.__init__(task, config, evaluation, actions, **overrides)  # type: ignore[misc]
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
        direction, counter-clockwise from the heading)."""
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
        result = None
        applied = action  # in this env's space
        u_rl = self.shield_input(action)
        penalty = 0.0
        if self.shield is not None:
            result = self.shield.filter_monitor(self.monitor, u_rl)
            u = result.action
            applied = self.env_action(u)
            penalty = self.params.correction_penalty * float(np.linalg.norm(u - u_rl))
        assert self._episode is not None  # set with _state
        self._episode[1].append(action.copy())
        obs, reward, cost, terminated, truncated, info = self._env.step(self.native_action(applied))
        goal_met = bool(info.get("goal_met", False))
        if goal_met:
            self._find_agent()
        self._state = self.true_state()
        if goal_met:  # a new goal was placed: the task starts again
            step = self.monitor.reset(self._state)
        else:
            step = self.monitor.advance(self._state)
        detour = self.detour()
        shaping = 0.0 if goal_met else self._reward_distance * (self._detour - detour)
        self._detour = detour
        info = {
            **info,
            "cost": float(cost),
            "violation": float(cost) > 0.0,
            "goal_met": goal_met,
            # What training's metrics count (as for every bundled env): a goal met is a
            # success, and the automaton's trap (inside a hazard's or a vase's disc) an entry.
            "success": goal_met,
            "trap": bool(step.trapped),
            "task_reward": float(reward),
            "detour": detour,
            "action": applied,
            "state": self._state,
        }
        if self.shield is not None:
            info["shield"] = shield_info(result, u_rl)
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
    **overrides: Any,
) -> gym.Env:
    """``gymnasium.make("tlshield/SafetyPointGoal1-v0", config=..., evaluation=...,
    actions=..., ...)``."""
    return SafetyGoalEnv(task, config, evaluation, actions, **overrides)


def hazard_attacker(env: SafetyGoalEnv, obs: NDArray[np.float64]) -> NDArray[np.float64]:
    """An attacker that sees what a policy sees: it steers at the nearest hazard on the hazard
    lidar and, from the velocimeter, drives at a speed that falls with the distance to it, so
    that it stops at the centre and stays there (full thrust ahead when no hazard is in
    range)."""
    robot = env.robot
    bins = env.lidar(obs, "hazards")
    if bins.max() <= 0.0:
        return env.drive(1.0, 0.0)
    i = int(np.argmax(bins))
    angle = (i + 0.5) * 2.0 * np.pi / bins.size - robot.ahead  # from the heading
    angle = (angle + np.pi) % (2.0 * np.pi) - np.pi  # (-pi, pi]: left is positive
    distance = env.lidar_range * (1.0 - bins[i])
    speed = min(1.0, 2.0 * distance)  # wanted, towards the hazard
    forward = robot.forward_speed(env.sensor(obs, "velocimeter"))
    thrust = float(np.clip(5.0 * (speed * math.cos(angle) - forward), -1.0, 1.0))
    return env.drive(thrust, float(np.clip(3.0 * angle, -1.0, 1.0)))
