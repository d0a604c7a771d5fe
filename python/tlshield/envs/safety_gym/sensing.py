"""The shield's state from what the agent senses (``SafetyGoalEnv(sensing="lidar")``): no
MuJoCo position is read.

Each step the state is written in the frame of the agent's body at that step (the lidars'
frame: origin at the body, +x its x axis), so the robot's position is known exactly there:

- **The robot.** The Point at the origin, heading 0 (its +x is its heading), its velocity the
  velocimeter's two planar values; the Car's ``x, y`` the point ``pivot`` behind the origin
  along its heading (its -y axis, :attr:`~tlshield.envs.safety_gym.robots.CarModel.ahead`),
  its speed the velocimeter's along that heading.
- **Hazards and vases.** One obstacle per lidar bin, on the bin's middle ray. No centre the
  bin may hold is nearer than the bin's floor (:func:`~tlshield.envs.safety_gym.lidar.floors`),
  so from wherever the robot is ``delta`` after the reading, every such centre is at most
  ``2 delta`` nearer than the point at the floor on that ray. The hazards' and the vases'
  readings share one obstacle per bin (the atoms stay within the automaton's limit): with
  ``radii`` the barrier radius of each kind and ``R`` the shared one (the first kind's), the
  point sits at ``min_k (floor_k - radius_k) + R``, so that its clearance ``|p - point| - R``
  is the smaller of the two kinds' at the reading, and, ``delta`` later, each kind's
  clearance to every centre it may hold is at least the point's less ``2 delta``. The
  barrier's radius grows by
  :attr:`~tlshield.envs.safety_gym.task.SafetyGoalParams.lidar_slack` for that ``2 delta``. A
  bin reading 0 places its point at the lidar's range.
- **The goal.** The goal lidar's one object, exact within the lidar's range
  (:func:`~tlshield.envs.safety_gym.lidar.nearest`). Beyond it the last goal seen is carried by
  odometry: the heading from the magnetometer (the world's field in the body frame), the
  position integrated from the velocimeter over the env's step. Before any goal is seen the
  goal is placed :data:`UNSEEN_GOAL` metres ahead, so that the CLF drives out to look.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from tlshield.envs.safety_gym import lidar as L

#: Where the goal is placed before the goal lidar has seen one (m ahead): past its range.
UNSEEN_GOAL = L.MAX_DIST + 1.0
#: Where a bin that reads nothing places its obstacle (m): beyond every goal and every route.
EMPTY = 30.0


def heading_of(magnetometer: NDArray[np.float64]) -> float:
    """The world heading of the body's +x axis from the magnetometer (MuJoCo's field is
    ``(0, -0.5, 0)`` in the world: in the body frame ``-0.5 (sin psi, cos psi, .)``)."""
    return math.atan2(-float(magnetometer[0]), -float(magnetometer[1]))


class LidarState:
    """Writes the shield's state from observations (see the module docs). ``sensor(obs,
    name)`` reads one entry of the flat observation; ``agent_dim``, ``ahead`` and ``pivot``
    are the robot's; ``radii`` maps each lidar read (``"hazards"``, ``"vases"``) to its
    barrier radius (m), the first being the one the obstacles share (one slot per bin).
    :meth:`reset` gives the env's step (s), for the odometry."""

    def __init__(
        self,
        sensor: Callable[[NDArray[np.float64], str], NDArray[np.float64]],
        *,
        agent_dim: int,
        ahead: float,
        pivot: float,
        radii: dict[str, float],
        lidar: L.Lidar = L.GOAL_TASKS,
    ) -> None:
        self._sensor = sensor
        self.agent_dim = agent_dim
        self.ahead = ahead
        self.pivot = pivot
        if not radii:
            raise ValueError("LidarState: expected at least one lidar to read")
        self.radii = dict(radii)
        self.shared = next(iter(self.radii.values()))
        self.period = 0.0
        self.lidar = lidar
        self.dim = agent_dim + 2 * (1 + lidar.bins)
        mid = (np.arange(lidar.bins) + 0.5) * lidar.width
        self._rays = np.column_stack([np.cos(mid), np.sin(mid)])
        self._odometry = np.zeros(2)
        self._goal: NDArray[np.float64] | None = None

    def reset(self, period: float) -> None:
        """Forgets the odometry and the goal (a new episode), whose steps last ``period``
        seconds."""
        self.period = period
        self._odometry[:] = 0.0
        self._goal = None

    def forget_goal(self) -> None:
        """Forgets the goal carried by odometry (a goal was met: a new one is placed)."""
        self._goal = None

    def read(self, obs: NDArray[np.float64]) -> NDArray[np.float64]:
        """The state of this observation, and the odometry advanced over the step it ends."""
        sensor = self._sensor
        heading = heading_of(sensor(obs, "magnetometer"))
        velocity = np.asarray(sensor(obs, "velocimeter"), dtype=np.float64)[:2]
        c, s = math.cos(heading), math.sin(heading)
        # The body's velocity in the odometry's (world-aligned) frame.
        world_v = np.array([c * velocity[0] - s * velocity[1], s * velocity[0] + c * velocity[1]])
        self._odometry += self.period * world_v
        out = np.zeros(self.dim)
        if self.agent_dim == 5:  # the Point: x, y, theta, vx, vy in the body frame
            out[3:5] = velocity
        else:  # the Car: x, y, psi, v
            out[0] = -self.pivot * math.cos(self.ahead)
            out[1] = -self.pivot * math.sin(self.ahead)
            out[2] = self.ahead
            out[3] = math.cos(self.ahead) * velocity[0] + math.sin(self.ahead) * velocity[1]
        goal = L.nearest(sensor(obs, "goal_lidar"), self.lidar)
        if goal is not None:
            ego = goal[0] * np.array([math.cos(goal[1]), math.sin(goal[1])])
            self._goal = self._odometry + np.array(
                [c * ego[0] - s * ego[1], s * ego[0] + c * ego[1]]
            )
        elif self._goal is not None:
            rel = self._goal - self._odometry
            ego = np.array([c * rel[0] + s * rel[1], -s * rel[0] + c * rel[1]])
        else:
            ego = UNSEEN_GOAL * np.array([math.cos(self.ahead), math.sin(self.ahead)])
        at = self.agent_dim
        out[at : at + 2] = ego
        clearance = np.full(self.lidar.bins, np.inf)
        seen = np.zeros(self.lidar.bins, dtype=bool)
        for kind, radius in self.radii.items():
            reads = sensor(obs, f"{kind}_lidar")
            seen |= np.asarray(reads) > 0.0
            clearance = np.minimum(clearance, L.floors(reads, self.lidar) - radius)
        # A bin that reads nothing holds no centre within the lidar's range, farther than the
        # robot moves in a step: its point stands out of the way, so that the router does
        # not plan around a ring of discs at the range that nothing put there.
        distance = np.where(seen, clearance + self.shared, EMPTY)
        out[at + 2 :] = (distance[:, None] * self._rays).ravel()
        return out
