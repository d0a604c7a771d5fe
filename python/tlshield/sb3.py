"""Stable-Baselines3 ``VecEnv`` wrapper that shields all sub-environments in one call. Importing
this module loads SB3 (and torch): install the ``train`` extra."""

from __future__ import annotations

import functools
import inspect
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from tlshield._core import Shield
from tlshield.copying import IndependentCopies
from tlshield.envs.params import FULL
from tlshield.vector import ActionFn, batch_infos, rl_actions, split_states


class ShieldedVecEnv(IndependentCopies, VecEnvWrapper):  # type: ignore[misc]
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

    def __getstate__(self) -> dict[str, Any]:
        # SB3's VecEnvWrapper keeps its class's members (a mappingproxy among them, which no
        # pickle takes); they are the class's, so a copy looks them up again.
        state = self.__dict__.copy()
        state.pop("class_attributes", None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self.class_attributes = dict(inspect.getmembers(self.__class__))

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


class WorldVecEnv(IndependentCopies, VecEnv):  # type: ignore[misc]
    """Stable-Baselines3 ``VecEnv`` of a :class:`tlshield.vector.WorldBatch` (N bundled envs
    stepped in one core call). It gives what SB3's ``DummyVecEnv`` over the same single envs
    gives, bit for bit (observations, float32 rewards, dones, ``terminal_observation``, the
    reset seeds ``seed + i``), and every env's ``info`` as the single env builds it (no CLF
    goal or barrier list in ``info["shield"]``)."""

    def __init__(self, batch: Any) -> None:
        self.batch = batch
        super().__init__(len(batch.envs), batch.observation_space, batch.action_space)
        self._actions: NDArray[np.float64] | None = None

    @property
    def envs(self) -> list[Any]:
        """The single environments."""
        return self.batch.envs

    def reset(self) -> NDArray[np.float64]:
        for i in range(self.num_envs):
            options = {"options": self._options[i]} if self._options[i] else {}
            _, self.reset_infos[i] = self.batch.reset_env(i, seed=self._seeds[i], **options)
        self._reset_seeds()
        self._reset_options()
        return self.batch.obs.copy()

    def step_async(self, actions: NDArray[Any]) -> None:
        self._actions = np.asarray(actions, dtype=np.float64)

    def step_wait(self) -> Any:
        if self._actions is None:
            raise RuntimeError("call step_async() before step_wait()")
        out = self.batch.step(self._actions)
        self._actions = None
        rewards = out.reward.astype(np.float32)  # DummyVecEnv's reward buffer is float32
        dones = out.terminated | out.truncated
        infos = self.batch.infos(out)
        for info, cut in zip(infos, (out.truncated & ~out.terminated).tolist(), strict=True):
            info["TimeLimit.truncated"] = cut
        for i in np.flatnonzero(dones):
            infos[i]["terminal_observation"] = self.batch.obs[i].copy()
            _, self.reset_infos[i] = self.batch.reset_env(int(i))
        return self.batch.obs.copy(), rewards, dones, infos

    def close(self) -> None:
        for env in self.envs:
            env.close()

    def _indices(self, indices: Any) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        return [indices] if isinstance(indices, int) else list(indices)

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self.envs[i], attr_name) for i in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        for i in self._indices(indices):
            setattr(self.envs[i], attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any
    ) -> list[Any]:
        return [
            getattr(self.envs[i], method_name)(*method_args, **method_kwargs)
            for i in self._indices(indices)
        ]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False for _ in self._indices(indices)]


class ChannelVecEnv(WorldVecEnv):  # type: ignore[misc]
    """``num_envs`` Channel-v0 envs as one SB3 ``VecEnv`` (see :class:`WorldVecEnv`)."""

    def __init__(self, num_envs: int, config: str = FULL, **kwargs: Any) -> None:
        from tlshield.vector import ChannelBatch

        super().__init__(ChannelBatch(num_envs, config, **kwargs))


class PointMassVecEnv(WorldVecEnv):  # type: ignore[misc]
    """``num_envs`` PointMass-v0 envs as one SB3 ``VecEnv`` (see :class:`WorldVecEnv`)."""

    def __init__(self, num_envs: int, config: str = FULL, **kwargs: Any) -> None:
        from tlshield.vector import PointMassBatch

        super().__init__(PointMassBatch(num_envs, config, **kwargs))


def make_vec_env(
    env_id: str, num_envs: int, config: str = FULL, *, seed: int | None = None, **kwargs: Any
) -> VecEnv:
    """An SB3 ``VecEnv`` of ``num_envs`` copies of ``env_id`` in shield configuration
    ``config`` (``kwargs``: the env factory's keywords). An env registered with a core world
    as its ``vector_entry_point`` (Channel-v0, PointMass-v0) steps all its copies in one core
    call, the same numbers as SB3's ``DummyVecEnv`` over the single envs, bit for bit; any
    other env runs in a ``DummyVecEnv`` of ``gymnasium.make`` copies. ``seed``: copy ``i`` is
    seeded ``seed + i`` (SB3's ``VecEnv.seed``)."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    from tlshield.vector import _check_count, world_vector_class

    _check_count(num_envs)
    kind = world_vector_class(env_id)
    if kind is not None:
        venv: VecEnv = WorldVecEnv(kind.BATCH(num_envs, config, **kwargs))
    else:
        one = functools.partial(gym.make, env_id, config=config, **kwargs)
        venv = DummyVecEnv([one] * num_envs)
    if seed is not None:
        venv.seed(seed)
    return venv
