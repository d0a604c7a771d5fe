"""Shielding N environments in one call: the per-env ``info["shield"]`` of a batch, the
layout of FSA-augmented observations, and :class:`ShieldedVectorEnv` (Gymnasium's vector API).
The Stable-Baselines3 twin, :class:`tlshield.sb3.ShieldedVecEnv`, lives apart so that SB3 and
torch load only when it is used."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from tlshield._core import FilterBatch, Shield
from tlshield.codes import Solver, Status

#: Maps the policy's actions ``(N, m)`` to the RL actions in the shield's units.
ActionFn = Callable[[NDArray[np.float64]], NDArray[np.float64]]


def batch_infos(out: FilterBatch, a_rl: NDArray[np.float64]) -> list[dict[str, Any]]:
    """Per-env ``info["shield"]`` of a batch (lists of floats: cheaper than array rows): the
    single-env entry's fields but the goal and the barriers, which a batch does not return."""
    columns = zip(
        a_rl.tolist(),
        out.a_cbf.tolist(),
        out.a_clf.tolist(),
        out.delta.tolist(),
        out.status.tolist(),
        out.slack.tolist(),
        out.solver.tolist(),
        strict=True,
    )
    return [
        {
            "a_rl": a,
            "a_cbf": cbf,
            "a_clf": clf,
            "delta": delta,
            "status": Status(status),
            "slack": slack,
            "solver": Solver(solver),
        }
        for a, cbf, clf, delta, status, slack, solver in columns
    ]


def rl_actions(actions: Any, action_fn: ActionFn | None) -> NDArray[np.float64]:
    """The batch's RL actions in the shield's units, as one C-ordered float64 array."""
    a = np.asarray(actions, dtype=np.float64)
    return np.ascontiguousarray(a if action_fn is None else action_fn(a), dtype=np.float64)


def split_states(obs: NDArray[np.float64], k: int) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """States and FSA states from a batch of FSA-augmented observations."""
    return np.ascontiguousarray(obs[:, :-k]), np.argmax(obs[:, -k:], axis=1)


class ShieldedVectorEnv(gym.vector.VectorWrapper):
    """Shields every sub-environment of a Gymnasium vector env in one ``filter_batch`` call.

    The sub-environments are FSA-augmented envs without their own shield whose observation is
    the state vector followed by the one-hot FSA state, and whose ``step`` takes the applied
    action (as ``tlshield/Channel-v0`` with ``shield_in_env=False``). ``action_fn`` maps the
    policy's actions ``(N, m)`` to the RL actions in the shield's units (default: as they
    are). ``infos["shield"]`` holds one dict per sub-env.
    """

    def __init__(
        self, env: gym.vector.VectorEnv, shield: Shield, action_fn: ActionFn | None = None
    ) -> None:
        super().__init__(env)
        self.shield = shield
        self.action_fn = action_fn
        self._k = shield.automaton.num_states
        self._obs: NDArray[np.float64] | None = None

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self._obs = np.asarray(obs, dtype=np.float64)
        return obs, info

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
        if self._obs is None:
            raise RuntimeError("call reset() before step()")
        a_rl = rl_actions(actions, self.action_fn)
        states, qs = split_states(self._obs, self._k)
        out = self.shield.filter_batch(states, qs, a_rl)
        obs, rewards, terminated, truncated, infos = self.env.step(out.action)
        self._obs = np.asarray(obs, dtype=np.float64)
        infos = {**infos, "shield": batch_infos(out, a_rl)}
        return obs, rewards, terminated, truncated, infos
