"""The shield's state from what the agent senses (``SafetyGoalEnv(sensing="lidar")``): no
MuJoCo position is read.

Each step the state is written in the frame of the agent's body at that step (the lidars'
frame: origin at the body, +x its x axis), so the robot's position is known exactly there:

- **The robot.** The Point at the origin, heading 0 (its +x is its heading), its velocity the
  velocimeter's two planar values; the Car's ``x, y`` the point ``pivot`` behind the origin
  along its heading (its -y axis, :attr:`~tlshield.envs.safety_gym.robots.CarModel.ahead`),
  its speed the velocimeter's along that heading.
- **Hazards and vases: one obstacle point per lidar bin.** The hazards' and the vases'
  readings share it (the atoms stay within the automaton's limit). With ``radius_k`` each
  kind's barrier radius, ``R`` the shared one (the first kind's) and ``floor_k`` the bin's
  floor (:func:`~tlshield.envs.safety_gym.lidar.floors`: no centre of kind ``k`` in the bin is
  nearer), the bin's clearance is ``c_b = min_k (floor_k - radius_k)``.

  *The bound.* Over the step a reading serves the robot moves at most ``delta = |v| T + A
  T^2 / 2`` from the origin (``v`` the velocimeter's, ``T`` the env's step, ``A`` =
  :data:`ACCEL`). Let a point ``q = D u`` (``|u| = 1``) stand for the bin, with ``D <= c_b + R
  - s`` and ``u`` within angle ``eps`` of every direction in the bin. For ``|p| <= delta`` and
  any centre ``x`` of kind ``k`` the bin may hold, ``|p - x| - radius_k >= c_b - p . u_x`` and
  ``|p - q| - R <= D - R - p . u + delta^2 / (2 (D - delta))``, so the barrier ``|p - q| - R``
  never exceeds the true clearance once ``s = 2 delta sin(eps / 2) + delta^2 / (2 (R -
  delta))`` (``D >= R`` while the barrier holds). The direction is free within ``eps``; the
  distance alone carries the bound.

  *The point.* Its direction is where a centre at the floor may lie
  (:func:`~tlshield.envs.safety_gym.lidar.arcs`, the middle of the arc, of the kind that
  sets ``c_b``). A bin next to a nearer bin that is nearest among its own neighbours stands on
  that bin's point: its reading is most often that object's alias spill, which would
  otherwise read as a second obstacle behind it, and every centre it may hold is within two
  bins' angle of that point and no nearer than its distance. So ``eps`` is two bins' angle,
  and ``s`` is computed each step from ``delta``. A bin that reads 0 holds no centre within
  the lidar's range, which the robot cannot cross in a step: its point stands out of the way,
  :data:`EMPTY` metres off, so that the router plans around nothing there.
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
#: The bound on the robot's acceleration over a step (m/s^2) that ``delta`` assumes: over
#: three times the Point's full thrust (2.8 m/s^2); its share of ``delta`` is 2 mm.
ACCEL = 10.0


def heading_of(magnetometer: NDArray[np.float64]) -> float:
    """The world heading of the body's +x axis from the magnetometer (MuJoCo's field is
    ``(0, -0.5, 0)`` in the world: in the body frame ``-0.5 (sin psi, cos psi, .)``)."""
    return math.atan2(-float(magnetometer[0]), -float(magnetometer[1]))


def slack(delta: float, radius: float, lidar: L.Lidar = L.GOAL_TASKS) -> float:
    """How much nearer (m) than the true clearance an obstacle point's barrier may read once
    the robot has moved ``delta`` from where the lidar read, for a point within two bins'
    angle of every centre it stands for and a barrier of ``radius`` (see the module docs).
    Infinite when ``delta`` reaches the radius."""
    if delta >= radius:
        return math.inf
    return 2.0 * delta * math.sin(lidar.width) + delta * delta / (2.0 * (radius - delta))


class LidarState:
    """Writes the shield's state from observations (see the module docs). ``sensor(obs,
    name)`` reads one entry of the flat observation; ``agent_dim``, ``ahead`` and ``pivot``
    are the robot's; ``radii`` maps each lidar read (``"hazards"``, ``"vases"``) to its
    barrier radius (m), the first being the one the obstacles share (one slot per bin).
    :meth:`reset` gives the env's step (s), for the odometry and the bound."""

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
        #: The bound on the robot's motion over the step the last reading serves (m).
        self.delta = 0.0
        self._bins = np.arange(lidar.bins)
        mid = (self._bins + 0.5) * lidar.width
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
        # Read every step: the planar values as floats, numpy only across the bins.
        sensor = self._sensor
        heading = heading_of(sensor(obs, "magnetometer"))
        vx, vy = (float(v) for v in sensor(obs, "velocimeter")[:2])
        c, s = math.cos(heading), math.sin(heading)
        # The body's velocity in the odometry's (world-aligned) frame.
        self._odometry[0] += self.period * (c * vx - s * vy)
        self._odometry[1] += self.period * (s * vx + c * vy)
        out = np.zeros(self.dim)
        if self.agent_dim == 5:  # the Point: x, y, theta, vx, vy in the body frame
            out[3], out[4] = vx, vy
        else:  # the Car: x, y, psi, v
            out[0] = -self.pivot * math.cos(self.ahead)
            out[1] = -self.pivot * math.sin(self.ahead)
            out[2] = self.ahead
            out[3] = math.cos(self.ahead) * vx + math.sin(self.ahead) * vy
        at = self.agent_dim
        goal = L.nearest(sensor(obs, "goal_lidar"), self.lidar)
        if goal is not None:
            ex, ey = goal[0] * math.cos(goal[1]), goal[0] * math.sin(goal[1])
            self._goal = self._odometry + np.array([c * ex - s * ey, s * ex + c * ey])
        elif self._goal is not None:
            rx, ry = (float(v) for v in self._goal - self._odometry)
            ex, ey = c * rx + s * ry, -s * rx + c * ry
        else:
            ex, ey = UNSEEN_GOAL * math.cos(self.ahead), UNSEEN_GOAL * math.sin(self.ahead)
        out[at], out[at + 1] = ex, ey
        t = self.period
        self.delta = math.hypot(vx, vy) * t + 0.5 * ACCEL * t * t
        out[at + 2 :] = self.points(obs, self.delta).ravel()
        return out

    def points(self, obs: NDArray[np.float64], delta: float) -> NDArray[np.float64]:
        """The obstacle point of each bin (``(bins, 2)``, the body frame) for a robot that moves
        at most ``delta`` (m) over the step (see the module docs)."""
        sensor, lidar = self._sensor, self.lidar
        clearance = np.full(lidar.bins, np.inf)
        bearing = np.zeros(lidar.bins)
        seen = np.zeros(lidar.bins, dtype=bool)
        for kind, radius in self.radii.items():
            reads = sensor(obs, f"{kind}_lidar")
            near = L.floors(reads, lidar) - radius
            lo, hi = L.arcs(reads, lidar)
            # The direction of the kind that sets the bin's clearance.
            bearing = np.where(near < clearance, 0.5 * (lo + hi), bearing)
            clearance = np.minimum(clearance, near)
            seen |= reads > 0.0
        near = np.where(seen, clearance, np.inf)
        before, after = near[lidar.before], near[lidar.after]
        # Bins nearest among their neighbours, and which neighbour (if any) each bin stands on.
        anchor = seen & (near <= before) & (near <= after)
        left = np.where(anchor[lidar.before] & (before < near), before, np.inf)
        right = np.where(anchor[lidar.after] & (after < near), after, np.inf)
        neighbour = np.where(left <= right, lidar.before, lidar.after)
        on = np.where(np.minimum(left, right) < np.inf, neighbour, self._bins)
        distance = np.where(seen, clearance + self.shared - slack(delta, self.shared, lidar), EMPTY)
        rays = np.where(
            seen[:, None], np.column_stack([np.cos(bearing), np.sin(bearing)]), self._rays
        )
        return distance[on, None] * rays[on]
