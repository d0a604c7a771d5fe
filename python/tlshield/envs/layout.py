"""The channel case study's 13-value state, once for the environment, its renderer and the
figures: ``[x, y, theta, g1x, g1y, g2x, g2y, g3x, g3y, o1x, o1y, o2x, o2y]`` (paper Sec. VI)."""

#: Length of the state vector.
STATE_DIM = 13

#: Index of each named state value.
X, Y, THETA = 0, 1, 2
#: The (x, y) indices of the goals g1, g2, g3.
GOAL_DIMS = ((3, 4), (5, 6), (7, 8))
#: The (x, y) indices of the obstacles o1, o2.
OBSTACLE_DIMS = ((9, 10), (11, 12))
