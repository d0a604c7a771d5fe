"""What evaluation records of a Channel-v0 episode for the trajectory figure: the start state,
the agent's path and the obstacles' paths. A :class:`tlshield.lab.evaluation.Recorder`, named
by Channel-v0's profile (:mod:`tlshield.envs.profile`); evaluation saves its arrays as
``trajectories.npz``, which :mod:`tlshield.lab.runs` reads back."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from tlshield.envs.layout import OBSTACLE_DIMS, X, Y

__all__ = ["ChannelPaths"]

#: The obstacles' centres in the state, ``[o1x, o1y, o2x, o2y]``.
_OBSTACLES = [i for dims in OBSTACLE_DIMS for i in dims]


class ChannelPaths:
    """Per trial, the start state and the agent's and obstacles' positions at every step."""

    def __init__(self) -> None:
        self.starts: dict[int, NDArray[np.float64]] = {}
        self.paths: dict[int, list[NDArray[np.float64]]] = {}
        self.obstacles: dict[int, list[NDArray[np.float64]]] = {}

    def start(self, trial: int, env: Any) -> None:
        """After the trial's reset: its start state and first positions."""
        state = env.unwrapped.state
        self.starts[trial] = state.copy()
        self.paths[trial] = [state[[X, Y]]]
        self.obstacles[trial] = [state[_OBSTACLES]]

    def step(self, trial: int, env: Any) -> None:
        """After each of the trial's steps: the positions it reached."""
        state = env.unwrapped.state
        self.paths[trial].append(state[[X, Y]])
        self.obstacles[trial].append(state[_OBSTACLES])

    def end(self, trial: int, env: Any, info: dict[str, Any], terminated: bool) -> dict[str, Any]:
        """Adds nothing to the trial's outcome."""
        return {}

    def arrays(self) -> dict[str, NDArray[Any]]:
        """``starts`` (trials x state), ``lengths`` (steps + 1 per trial), ``paths`` and
        ``obstacle_paths`` (every trial's positions, concatenated in trial order)."""
        trials = sorted(self.starts)
        if not trials:
            return {}
        paths = [np.array(self.paths[i]) for i in trials]
        return {
            "starts": np.stack([self.starts[i] for i in trials]),
            "lengths": np.array([len(p) for p in paths]),
            "paths": np.concatenate(paths),
            "obstacle_paths": np.concatenate([np.array(self.obstacles[i]) for i in trials]),
        }
