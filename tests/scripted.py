"""Scripted controllers on Channel-v0 for reward-loophole checks: finish the task, park outside
the first goal, barge straight through an obstacle or go around it."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from tlshield.envs.channel import GOAL_DIMS, THETA, ChannelEnv, X, Y

Policy = Callable[[ChannelEnv], np.ndarray]


def towards(env: ChannelEnv, target: np.ndarray, speed: float = 1.0) -> np.ndarray:
    """The normalised action that moves the reference point straight at ``target``."""
    s = env.state
    d = np.asarray(target, dtype=float) - s[X : Y + 1]
    dist = float(np.linalg.norm(d))
    vel = d / max(dist, 1e-9) * min(speed, dist / env.params.agent.dt)
    th, eps = s[THETA], env.params.agent.eps
    a = np.array(
        [
            math.cos(th) * vel[0] + math.sin(th) * vel[1],
            (-math.sin(th) * vel[0] + math.cos(th) * vel[1]) / eps,
        ]
    )
    lo, hi = (np.asarray(b, dtype=float) for b in env.params.agent.rl_bounds)
    return np.clip((a - (hi + lo) / 2) / ((hi - lo) / 2), -1.0, 1.0)


def first_goal(env: ChannelEnv) -> np.ndarray:
    """The nearer of g1/g2 that lies inside the channel."""
    s, cfg = env.state, env.params
    inside = []
    for a, b in GOAL_DIMS[:2]:
        g = s[a : b + 1]
        if (
            abs(g[1] - g[0]) / math.sqrt(2)
            <= cfg.task.half_width / math.sqrt(2) - cfg.task.goal_radius
        ):
            inside.append(g.copy())
    return min(inside, key=lambda g: float(np.linalg.norm(g - s[X : Y + 1])))


def finish(env: ChannelEnv) -> np.ndarray:
    """Drives straight to the first goal, then straight to g3."""
    if env.tracker.q == env.tracker.automaton.initial:
        return towards(env, first_goal(env))
    return towards(env, env.state[7:9])


def park(env: ChannelEnv) -> np.ndarray:
    """Stops 5 cm outside the first goal."""
    g, p = first_goal(env), env.state[X : Y + 1]
    d = g - p
    stop = env.params.task.goal_radius + 0.05
    if np.linalg.norm(d) <= stop:
        return towards(env, p, speed=0.0)
    return towards(env, g - d / np.linalg.norm(d) * stop)


def discounted_return(
    env: ChannelEnv, policy: Policy, seed: int, gamma: float | None = None
) -> tuple[float, bool, int]:
    """``(discounted return, success, collision steps)`` of one episode, discounted with the
    environment's training discount unless ``gamma`` is given."""
    gamma = env.params.task.gamma if gamma is None else gamma
    env.reset(seed=seed)
    total, discount, collisions, info = 0.0, 1.0, 0, {"success": False}
    for _ in range(env.params.task.horizon):
        _, reward, terminated, truncated, info = env.step(policy(env))
        total += discount * reward
        discount *= gamma
        collisions += info["collision"]
        if terminated or truncated:
            break
    return total, bool(info["success"]), collisions
