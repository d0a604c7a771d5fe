"""The channel case study's 13-value state, once for the environment, its renderer and the
figures: ``[x, y, theta, g1x, g1y, g2x, g2y, g3x, g3y, o1x, o1y, o2x, o2y]`` (paper Sec. VI)."""

from tlshield._core import ChannelWorld as _World

# Read from the core, which steps the world: one model of the layout (channel.rs).
#: Length of the state vector.
STATE_DIM: int = _World.STATE_DIM

#: Index of each named state value.
X, Y, THETA = _World.X, _World.Y, _World.THETA
#: The (x, y) indices of the goals g1, g2, g3.
GOAL_DIMS: tuple[tuple[int, int], ...] = tuple(_World.GOAL_DIMS)
#: The (x, y) indices of the obstacles o1, o2.
OBSTACLE_DIMS: tuple[tuple[int, int], ...] = tuple(_World.OBSTACLE_DIMS)
#: Length of the relative observation, before the one-hot FSA state.
RELATIVE_DIM: int = _World.RELATIVE_DIM
