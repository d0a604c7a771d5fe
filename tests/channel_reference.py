"""An independent numpy version of one Channel-v0 step (the Python environment's code before
the world moved into the core), to check the core's ``ChannelWorld`` against."""

from __future__ import annotations

import math

import numpy as np

from tlshield.envs.channel import ChannelParams
from tlshield.envs.layout import OBSTACLE_DIMS, THETA, X, Y

SQRT2 = math.sqrt(2.0)


def obstacle_positions(paths: np.ndarray, t: float) -> np.ndarray:
    """Centres (2, 2) of obstacles on ``paths`` (u, amplitude, frequency, phase) at time t."""
    out = np.empty((2, 2))
    for i, (u, amplitude, frequency, phase) in enumerate(paths):
        v = amplitude * math.sin(frequency * t + phase)
        out[i] = (u - v) / SQRT2, (u + v) / SQRT2
    return out


def next_state(
    cfg: ChannelParams, s: np.ndarray, applied: np.ndarray, paths: np.ndarray, t: int
) -> np.ndarray:
    """The state after applying ``applied`` at ``s`` (the ``t``-th step of the episode)."""
    v, w = applied
    nxt = s.copy()
    theta = s[THETA]
    nxt[X] = s[X] + cfg.agent.dt * (math.cos(theta) * v - cfg.agent.eps * math.sin(theta) * w)
    nxt[Y] = s[Y] + cfg.agent.dt * (math.sin(theta) * v + cfg.agent.eps * math.cos(theta) * w)
    nxt[THETA] = s[THETA] + cfg.agent.dt * w
    lo, hi = cfg.agent.arena
    nxt[X], nxt[Y] = min(max(nxt[X], lo), hi), min(max(nxt[Y], lo), hi)
    nxt[THETA] = (nxt[THETA] + math.pi) % (2 * math.pi) - math.pi
    for k, (a, b) in enumerate(OBSTACLE_DIMS):
        nxt[a], nxt[b] = obstacle_positions(paths, t * cfg.agent.dt)[k]
    return nxt


def observation(
    cfg: ChannelParams,
    s: np.ndarray,
    drift: np.ndarray,
    goal: np.ndarray | None,
    one_hot: np.ndarray,
) -> np.ndarray:
    """The relative observation, then the one-hot FSA state."""
    p = s[X : Y + 1]
    c, si = math.cos(s[THETA]), math.sin(s[THETA])
    frame = np.array([[c, si], [-si, c]])
    w = cfg.task.half_width
    obs = [c, si, s[X] - s[Y] + w, s[Y] - s[X] + w]
    obs += list(((s[3:9].reshape(3, 2) - p) @ frame.T).ravel())
    obs += list(((s[9:13].reshape(2, 2) - p) @ frame.T).ravel())
    obs += list((drift[9:13].reshape(2, 2) @ frame.T).ravel())
    obs += [0.0, 0.0] if goal is None else list(frame @ (goal - p))
    return np.concatenate([obs, one_hot])
