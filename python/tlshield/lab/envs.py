"""How the lab makes and checks environments: the trainer's and the evaluation's ``make``, the
checks run before training (a registered id, a task training can read) and an env's horizon.
What kind of task an env is, the lab reads from its profile (:mod:`tlshield.envs.profile`).
The library's own environments live in :mod:`tlshield.envs`."""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from typing import Any

import gymnasium as gym

from tlshield._removed import refuse
from tlshield.envs.profile import profile_of

__all__ = [
    "check_env_id",
    "check_task_env",
    "env_horizon",
    "factory_takes",
    "import_modules",
    "make",
]


def import_modules(modules: Sequence[str]) -> None:
    """Imports each module (a user's environments register themselves on import); a module
    that cannot be found is a ValueError naming it."""
    for name in modules:
        try:
            importlib.import_module(name)
        except ModuleNotFoundError as err:
            raise ValueError(
                f"import {name}: no module named {err.name!r} (run from the folder that holds "
                "it, or put that folder on PYTHONPATH)"
            ) from None


def check_env_id(env_id: str) -> None:
    """Raises ValueError unless ``env_id`` is a registered Gymnasium id. As in
    ``gymnasium.make``, ``"module:Env-v0"`` imports ``module`` first (where a user's
    environment registers itself)."""
    if ":" in env_id:
        module, _, env_id = env_id.partition(":")
        import_modules([module])
    if env_id not in gym.registry:
        tlshield_ids = sorted(k for k in gym.registry if k.startswith("tlshield/"))
        raise ValueError(
            f"env {env_id!r}: not a registered Gymnasium id (register your environment with "
            f"gymnasium.register first; bundled: {', '.join(tlshield_ids)})"
        )


def factory_takes(env_id: str, keyword: str) -> bool:
    """Whether the registered factory of ``env_id`` names ``keyword`` among its parameters
    (``**kwargs`` alone does not count: it may not reach the reward): the trainer then hands
    it its own value (``gamma``), so the task's reward is sized for the discount PPO uses."""
    import inspect

    name = env_id.partition(":")[2] or env_id
    entry = gym.spec(name).entry_point
    if isinstance(entry, str):
        module, _, attr = entry.partition(":")
        entry = getattr(importlib.import_module(module), attr)
    try:
        parameters = inspect.signature(entry).parameters.values()
    except (TypeError, ValueError):  # a builtin or C callable: no signature to read
        return False
    return any(p.name == keyword for p in parameters)


def env_horizon(env: Any) -> int | None:
    """The episode length of an environment: its parameters' ``horizon``, else its registered
    ``max_episode_steps`` (None when it says neither)."""
    try:
        return int(env.get_wrapper_attr("params").horizon)
    except AttributeError:
        spec = getattr(env, "spec", None)
        return getattr(spec, "max_episode_steps", None)


def check_task_env(env: Any, gamma: float, env_id: str) -> None:
    """Checks that ``env`` exposes a task that training can read, and that its reward's
    guarantees hold for this training: an :class:`tlshield.wrappers.FsaAugmented` in the
    wrapper chain (``info["success"]`` and ``info["trap"]``), a progress reward sized for PPO's
    ``gamma``, and a reward horizon no shorter than the episodes (else finishing late may not
    out-earn not finishing). Raises ValueError naming what is wrong. An env whose profile is
    ``scored_by_return`` has its own reward, so only its ``info`` is read."""
    if profile_of(env_id).scored_by_return:
        return
    try:
        tracker = env.get_wrapper_attr("tracker")
    except AttributeError:
        raise ValueError(
            f"env {env_id!r} exposes no task: wrap it in tlshield.wrappers.FsaAugmented (formula "
            "and predicates) and, for a shield, tlshield.wrappers.Shielded (model), and accept "
            "the keywords config= and evaluation="
        ) from None
    progress = tracker.progress
    if progress is None:
        return  # the paper's Eq. 5A1: no discount or horizon in its guarantees
    if abs(progress.gamma - gamma) > 1e-12:
        raise ValueError(
            f"env {env_id!r}: its progress reward is sized for gamma = {progress.gamma} but PPO "
            f"uses gamma = {gamma}; build the reward with the trainer's discount"
        )
    horizon = env_horizon(env)
    if horizon is not None and horizon > progress.horizon:
        raise ValueError(
            f"env {env_id!r}: episodes last up to {horizon} steps but the progress reward's bonus "
            f"is sized for a horizon of {progress.horizon}; pass horizon >= {horizon}"
        )


def make(env_id: str, config: str, **kwargs: Any) -> gym.Env:
    """One environment of ``env_id`` in shield configuration ``config``, through
    ``gym.make``."""
    check_env_id(env_id)  # an unknown id or module is one clear ValueError
    try:
        return gym.make(env_id, config=config, **kwargs)
    except TypeError as err:
        # Most often a factory that does not take the trainer's keywords: say which.
        keywords = ", ".join(f"{k}=" for k in ("config", *kwargs))
        raise ValueError(
            f"env {env_id!r}: gymnasium.make with {keywords} failed: {err} (the trainer's "
            "factory must accept config= and evaluation=)"
        ) from err


#: Names removed in 0.4, refused with a message naming what replaced them.
__getattr__ = refuse(
    __name__,
    {
        "scored_by_return": (
            "tlshield.envs.profile_of(env_id).scored_by_return (the env's registered EnvProfile)"
        )
    },
)
