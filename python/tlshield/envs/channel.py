"""The paper's case study (Li & Belta, Sec. VI): a channel, three goals, two moving obstacles.

State (13 values): reference point ``x, y``, heading ``theta``, goal centres ``g1, g2, g3``
(x, y each) and obstacle centres ``o1, o2`` (x, y each).
"""

from __future__ import annotations

from tlshield._core import Ball, Halfspace, Spec

#: The task: visit g1 or g2, then g3, staying inside the channel until g3 (paper Eq. 6C1).
TASK = "(F g1 | F g2) & F g3 & (!g3 U (g1 | g2)) & ((c1 & c2) U g3)"

#: Length of the state vector.
STATE_DIM = 13

#: Index of each named state value.
X, Y, THETA = 0, 1, 2
GOAL_DIMS = ((3, 4), (5, 6), (7, 8))
OBSTACLE_DIMS = ((9, 10), (11, 12))


def channel_task_spec(half_width: float = 1.5, goal_radius: float = 0.5) -> Spec:
    """The task spec over the 13-value state.

    Goals are balls of ``goal_radius`` around centres read from the state; the channel is
    ``c1: x - y + w > 0`` and ``c2: y - x + w > 0`` with ``w = half_width`` (paper Sec. VI).
    """
    c1 = [0.0] * STATE_DIM
    c1[X], c1[Y] = 1.0, -1.0
    c2 = [-v for v in c1]
    goals = {
        f"g{k + 1}": Ball(pos=[X, Y], radius=goal_radius, center_dims=list(dims))
        for k, dims in enumerate(GOAL_DIMS)
    }
    return Spec(TASK, {**goals, "c1": Halfspace(c1, half_width), "c2": Halfspace(c2, half_width)})
