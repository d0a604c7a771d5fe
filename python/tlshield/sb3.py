"""Stable-Baselines3 ``VecEnv`` wrapper that shields all sub-environments in one call. Importing
this module loads SB3 (and torch): install the ``train`` extra."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from tlshield._core import Shield
from tlshield.vector import ActionFn, batch_infos, rl_actions, split_states


class ShieldedVecEnv(VecEnvWrapper):  # type: ignore[misc]
    """Stable-Baselines3 ``VecEnv`` wrapper: shields all sub-environments in one
    ``filter_batch`` call per step (see :class:`tlshield.vector.ShieldedVectorEnv` for the
    layout and ``action_fn``). Each sub-env's ``info["shield"]`` carries its correction."""

    def __init__(self, venv: VecEnv, shield: Shield, action_fn: ActionFn | None = None) -> None:
        super().__init__(venv)
        self.shield = shield
        self.action_fn = action_fn
        self._k = shield.automaton.num_states
        self._obs: NDArray[np.float64] | None = None
        self._shield_infos: list[dict[str, Any]] = []

    def reset(self) -> Any:
        obs = self.venv.reset()
        self._obs = np.asarray(obs, dtype=np.float64)
        return obs

    def step_async(self, actions: NDArray[Any]) -> None:
        if self._obs is None:
            raise RuntimeError("call reset() before step()")
        a_rl = rl_actions(actions, self.action_fn)
        states, qs = split_states(self._obs, self._k)
        out = self.shield.filter_batch(states, qs, a_rl)
        self._shield_infos = batch_infos(out, a_rl)
        self.venv.step_async(out.action)

    def step_wait(self) -> Any:
        obs, rewards, dones, infos = self.venv.step_wait()
        # After an episode ends SB3 has already reset that sub-env: obs is its first state.
        self._obs = np.asarray(obs, dtype=np.float64)
        for info, shield in zip(infos, self._shield_infos, strict=True):
            info["shield"] = shield
        return obs, rewards, dones, infos
