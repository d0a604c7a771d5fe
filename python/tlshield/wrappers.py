"""Gymnasium wrappers that put a temporal-logic task and its shield around any environment.

* :class:`FsaAugmented` appends the one-hot FSA state to the observation and rewards progress
  through the task automaton (the progress reward by default, or the paper's Eq. 5A1).
* :class:`Shielded` filters every action through a :class:`tlshield.Shield` (Eq. 5D2).
* :class:`tlshield.sb3.ShieldedVecEnv` (Stable-Baselines3 ``VecEnv``) and
  :class:`tlshield.vector.ShieldedVectorEnv` (Gymnasium vector API) shield all
  sub-environments in one ``Shield.filter_batch`` call; both names are also reachable here, and
  SB3 (with torch) loads only when ``ShieldedVecEnv`` is first used.

Both single-env wrappers are thin: the automaton bookkeeping lives in :class:`FsaTracker`, the
shield call in :func:`shield_info`, and the paper's case study (``tlshield/Channel-v0``) is built
from the same two parts.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from tlshield._core import (
    DEFAULT_C_R,
    DEFAULT_GAMMA,
    DEFAULT_HORIZON,
    DEFAULT_PROGRESS_SCALE,
    DEFAULT_TRAP_PENALTY,
    Shield,
    Spec,
)
from tlshield.copying import IndependentCopies
from tlshield.step_info import shield_info
from tlshield.tracking import REWARDS, FsaTracker
from tlshield.vector import ShieldedVectorEnv

StateFn = Callable[[Any], NDArray[np.float64]]
DynamicsFn = Callable[[NDArray[np.float64]], tuple[NDArray[np.float64], NDArray[np.float64]]]


def identity_state(obs: Any) -> NDArray[np.float64]:
    """The default ``state_fn``: the observation is the state vector."""
    return np.asarray(obs, dtype=np.float64)


class FsaAugmented(IndependentCopies, gym.Wrapper):
    """Appends the one-hot FSA state to the observation and rewards the task.

    ``state_fn`` maps the wrapped env's observation to the state vector the spec's predicates
    read (default: the observation itself). The reward becomes ``r_tl + w * r_env``: ``w = 0``
    replaces the env's reward, ``w > 0`` augments it. ``info`` gains ``fsa_state``, ``success``
    (the accepting state is reached), ``trap`` and ``tl_reward``. With
    ``terminate_on_success`` the episode ends when the task is done, with ``terminate_on_trap``
    when it can no longer be done (the trap pays its penalty once, which the progress reward
    sizes so that entering the trap even at the last step loses). With
    ``failure_on_termination`` an episode the wrapped env ends before success (leaving the map)
    pays the trap penalty too, so ending early is never a way out.

    ``reward="progress"`` (default) pays the progress-aware reward
    (:class:`tlshield.ProgressReward`, built with ``gamma``, ``horizon``, ``scale``,
    ``exclusive`` and the other keywords in ``progress``); ``reward="paper"`` pays Eq. 5A1
    with ``trap_penalty``.
    """

    def __init__(
        self,
        env: gym.Env,
        spec: Spec,
        state_fn: StateFn = identity_state,
        *,
        c_r: float = DEFAULT_C_R,
        w: float = 0.0,
        trap_penalty: float = DEFAULT_TRAP_PENALTY,
        terminate_on_success: bool = True,
        terminate_on_trap: bool = False,
        failure_on_termination: bool = False,
        reward: str = "progress",
        gamma: float = DEFAULT_GAMMA,
        horizon: int = DEFAULT_HORIZON,
        scale: float = DEFAULT_PROGRESS_SCALE,
        exclusive: Sequence[Sequence[str]] = (),
        **progress: Any,
    ) -> None:
        super().__init__(env)
        if not isinstance(env.observation_space, gym.spaces.Box):
            raise TypeError("FsaAugmented needs a Box observation space")
        if reward not in REWARDS:
            raise ValueError(f"reward = {reward!r}: expected one of {REWARDS}")
        automaton = spec.automaton()
        shaped = None
        if reward == "progress":
            shaped = automaton.progress_reward(
                gamma=gamma,
                horizon=horizon,
                scale=scale,
                c_r=c_r,
                exclusive=[list(g) for g in exclusive],
                **progress,
            )
        self.tracker = FsaTracker(automaton, c_r, trap_penalty, shaped)
        self.state_fn = state_fn
        self.w = float(w)
        self.terminate_on_success = terminate_on_success
        self.terminate_on_trap = terminate_on_trap
        self.failure_on_termination = failure_on_termination
        box = env.observation_space
        k = self.tracker.automaton.num_states
        low = np.concatenate([box.low.ravel(), np.zeros(k)])
        high = np.concatenate([box.high.ravel(), np.ones(k)])
        self.observation_space = gym.spaces.Box(low, high, dtype=np.float64)

    @property
    def fsa_state(self) -> int:
        return self.tracker.q

    def _observe(self, obs: Any) -> NDArray[np.float64]:
        return np.concatenate([np.asarray(obs, dtype=np.float64).ravel(), self.tracker.one_hot()])

    def reset(self, **kwargs: Any) -> tuple[NDArray[np.float64], dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        q = self.tracker.reset(self.state_fn(obs))
        info = {**info, "fsa_state": q, "success": self.tracker.success}
        info["trap"] = self.tracker.trapped
        return self._observe(obs), info

    def step(
        self, action: Any
    ) -> tuple[NDArray[np.float64], SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        q, r_tl = self.tracker.advance(self.state_fn(obs))
        info = {
            **info,
            "fsa_state": q,
            "success": self.tracker.success,
            "trap": self.tracker.trapped,
            "tl_reward": r_tl,
        }
        if terminated and self.failure_on_termination and not self.tracker.success:
            # The env ended the episode as a failure (e.g. leaving the map): pay what entering
            # the trap pays, so that ending early never beats going on.
            r_tl = self.tracker.trap_penalty
            info["tl_reward"] = r_tl
        terminated = (
            bool(terminated)
            or (self.terminate_on_success and self.tracker.success)
            or (self.terminate_on_trap and self.tracker.trapped)
        )
        return self._observe(obs), r_tl + self.w * float(reward), terminated, truncated, info


class WithoutFsaState:
    """``Shielded``'s default ``state_fn``: the observation without its last ``k`` values (the
    one-hot FSA state). A class rather than a lambda, so that a shielded env pickles."""

    def __init__(self, k: int) -> None:
        self.k = k

    def __call__(self, obs: Any) -> NDArray[np.float64]:
        return np.asarray(obs, dtype=np.float64)[: -self.k]


class Shielded(IndependentCopies, gym.Wrapper):
    """Filters every action through ``shield`` before the wrapped env sees it.

    Must wrap an :class:`FsaAugmented` env (directly or further down): the shield needs the
    current FSA state. ``state_fn`` maps the observation (as the wrapped env returns it, FSA
    one-hot included) to the state vector; by default the first ``n`` values. ``dynamics_fn(s)``
    returns ``(f, g)`` for systems without a built-in model. ``drift_fn(s)`` returns the
    measured motion of state dimensions the agent does not control (moving obstacles), added
    to ``f`` (see ``Shield.filter``). ``action_fn`` maps the policy's action to the RL action
    in the shield's units (as the vector wrappers' ``action_fn``; default: as it is): the
    wrapped env then receives the shielded action in those units. ``info["shield"]`` carries
    ``a_rl``, ``a_cbf``, ``a_clf``, ``delta`` and ``status``; ``info["barriers"]`` each user
    barrier's value at the new state (:mod:`tlshield.lab.measures` counts a value below zero as a
    violation when the env reports none of its own).
    """

    def __init__(
        self,
        env: gym.Env,
        shield: Shield,
        state_fn: StateFn | None = None,
        dynamics_fn: DynamicsFn | None = None,
        drift_fn: StateFn | None = None,
        action_fn: StateFn | None = None,
    ) -> None:
        super().__init__(env)
        try:
            env.get_wrapper_attr("fsa_state")
        except AttributeError as err:
            raise TypeError("Shielded must wrap an FsaAugmented environment") from err
        self.shield = shield
        if shield.routes:
            # The task reward's goal term reads the way the shield drives (the reward and the
            # guidance agree), when the tracker watches the shield's own automaton.
            try:
                env.get_wrapper_attr("tracker").monitor.routed_by = shield
            except ValueError:
                warnings.warn(
                    "Shielded: the shield's automaton is not the FsaAugmented tracker's (build "
                    "both from one Spec), so the task reward's goal term keeps the straight "
                    "distance instead of the shield's routed way",
                    UserWarning,
                    stacklevel=2,
                )
        k = shield.automaton.num_states
        self.state_fn = state_fn or WithoutFsaState(k)
        self.dynamics_fn = dynamics_fn
        self.drift_fn = drift_fn
        self.action_fn = action_fn
        self._state: NDArray[np.float64] | None = None

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self._state = self.state_fn(obs)
        return obs, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        if self._state is None:
            raise RuntimeError("call reset() before step()")
        a_rl = np.asarray(action if self.action_fn is None else self.action_fn(action), float)
        q = self.env.get_wrapper_attr("fsa_state")
        drift = None if self.drift_fn is None else self.drift_fn(self._state)
        if self.dynamics_fn is None:
            result = self.shield.filter(self._state, q, a_rl, drift=drift)
        else:
            f, g = self.dynamics_fn(self._state)
            result = self.shield.filter(self._state, q, a_rl, f=f, g=g, drift=drift)
        obs, reward, terminated, truncated, info = self.env.step(result.action)
        self._state = self.state_fn(obs)
        info = {**info, "shield": shield_info(result, a_rl)}
        barriers = self.shield.barrier_values(self._state)
        if barriers:  # the new state's barrier values: what training and evaluation count
            info["barriers"] = barriers
        return obs, reward, terminated, truncated, info


def __getattr__(name: str) -> Any:
    # ShieldedVecEnv subclasses SB3's VecEnvWrapper: SB3 and torch load on first use only.
    if name == "ShieldedVecEnv":
        from tlshield.sb3 import ShieldedVecEnv

        return ShieldedVecEnv
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "REWARDS",
    "FsaAugmented",
    "FsaTracker",
    "Shielded",
    "ShieldedVectorEnv",
    "identity_state",
    "shield_info",
]
