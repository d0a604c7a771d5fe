"""The robots: Safety-Gymnasium's Point and Car as models the shield drives, identified from
MuJoCo.

This module owns the :class:`Robot` protocol (what the shielded env,
:class:`~tlshield.envs.safety_gym.env.SafetyGoalEnv`, asks of a robot), the two models that
satisfy it (:class:`PointModel`, :class:`CarModel`), their identified instances (:data:`POINT`,
:data:`CAR`) and the lookup by task (:func:`robot_of`).
"""

from __future__ import annotations

import math
import types
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from tlshield._core import ControlAffine, ThrustTurn


@runtime_checkable
class Robot(Protocol):
    """What :class:`~tlshield.envs.safety_gym.env.SafetyGoalEnv` reads of its robot
    (``env.robot``): exactly the attributes and methods the env uses. :class:`PointModel` and
    :class:`CarModel` satisfy it; the attributes are read-only (properties here, class or
    dataclass fields in the models). The models also give what policies reading the sensors
    use through ``env.robot`` and the env does not (``forward_speed``)."""

    @property
    def agent_dim(self) -> int:
        """How many values of the shield's state are the agent's (they come first)."""
        ...

    @property
    def defaults(self) -> dict[str, float]:
        """The robot's own defaults of ``SafetyGoalParams`` (keyword overrides win)."""
        ...

    @property
    def ahead(self) -> float:
        """The heading's angle in the body frame the lidars and sensors read (rad; the
        ``sensing="lidar"`` state places the robot's heading there)."""
        ...

    @property
    def pivot(self) -> float:
        """How far ahead of the state's ``x, y`` along the heading the barriers hold the body
        (m; 0: at ``x, y``)."""
        ...

    @property
    def scale(self) -> NDArray[np.float64]:
        """Safety-Gymnasium's action per unit of the robot's own (``actions="robot"``)."""
        ...

    def model(self, state_dim: int) -> ThrustTurn | ControlAffine:
        """The shield's core model over the ``state_dim`` values of the shield's state."""
        ...

    def input_box(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """The shield's action box ``(lo, hi)`` per input."""
        ...

    def shield_input(self, action: NDArray[np.float64]) -> NDArray[np.float64]:
        """Safety-Gymnasium's action in the shield's units."""
        ...

    def actuators(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        """The robot's own action (each actuator's working range as ``[-1, 1]``) for the
        shield's input ``u``."""
        ...

    def drive(self, thrust: float, turn: float) -> NDArray[np.float64]:
        """The robot's own action for a push along the heading and a turn, each in
        ``[-1, 1]``."""
        ...

    def locate(self, model: Any) -> Any:
        """Where the agent's pose and velocity are in MuJoCo's arrays (``model``: the
        ``MjModel``; called again whenever Safety-Gymnasium rebuilds the world)."""
        ...

    def read(self, data: Any, at: Any, s: NDArray[np.float64]) -> None:
        """Writes the agent's part of the shield's state into ``s[:agent_dim]`` from MuJoCo's
        ``data`` at the places ``at`` that :meth:`locate` gave."""
        ...


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
