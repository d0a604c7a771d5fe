"""What the lab needs to know about an environment, said once, where it is registered.

Gymnasium's :class:`gymnasium.envs.registration.EnvSpec` says how to build an env; an
:class:`EnvProfile` says what kind of task it is: scored by its return (Safety-Gymnasium's
tasks) or by a temporal-logic task's success, which parameters class its flat settings belong
to, which factory keywords are its task, what evaluation records of its episodes, how its
shield is rebuilt for a CLF-box schedule and which settings a preset implies. The lab
(:mod:`tlshield.lab`) reads the profile and never an env id.

:func:`register` registers an env with Gymnasium and its profile beside it; a user's env
registered with :func:`gymnasium.register` alone gets the default profile (a task scored by
success, its factory checking its own keywords). Objects a profile names (a class, a factory)
are ``"module:attr"`` strings, imported when the lab first needs them, as Gymnasium's entry
points are: registering imports nothing.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym

__all__ = ["EnvProfile", "load_attr", "profile_of", "register"]


@dataclass(frozen=True)
class EnvProfile:
    """What kind of task an environment is, for the lab (training, validation, evaluation).

    * ``scored_by_return``: the env is scored by its reward and cost (the goal moves when met
      and an episode runs to its horizon), not by a temporal-logic task's success. Training
      keeps the checkpoint with the best validation return, and evaluation runs the env as it
      trained (the unshielded ``rl`` unshielded), to the horizon.
    * ``params``: ``"module:Class"`` of its parameters (:mod:`tlshield.envs.params`' flat
      names are the settings ``--set`` accepts); None: its factory checks its own keywords.
    * ``task_keywords``: factory keywords that are the task, not parameters (``formula``).
    * ``recorder``: ``"module:factory"`` of a :class:`tlshield.lab.evaluation.Recorder` whose
      arrays evaluation saves as ``trajectories.npz`` (Channel-v0's paths); None: none.
    * ``clf_shield``: ``"module:fn"``, ``fn(params, config) -> Shield``: the shield rebuilt from
      parameters, which a CLF-box schedule (``clf_schedule``) sets on the training envs; None:
      the env has no schedule.
    * ``preset_overrides``: per preset name, the env settings that preset implies (the paper's
      preset trains Channel-v0 in the paper's own environment).
    """

    scored_by_return: bool = False
    params: str | None = None
    task_keywords: tuple[str, ...] = ()
    recorder: str | None = None
    clf_shield: str | None = None
    preset_overrides: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.scored_by_return, bool):
            raise TypeError(
                f"EnvProfile.scored_by_return = {self.scored_by_return!r}: expected a bool"
            )
        for name in ("params", "recorder", "clf_shield"):
            value = getattr(self, name)
            if value is not None and (not isinstance(value, str) or ":" not in value):
                raise TypeError(f"EnvProfile.{name} = {value!r}: expected 'module:attr' or None")
        keywords = self.task_keywords
        if isinstance(keywords, str) or not all(isinstance(k, str) for k in keywords):
            raise TypeError(f"EnvProfile.task_keywords = {keywords!r}: expected names (str)")
        object.__setattr__(self, "task_keywords", tuple(keywords))
        if not isinstance(self.preset_overrides, Mapping) or not all(
            isinstance(v, Mapping) for v in self.preset_overrides.values()
        ):
            raise TypeError(
                f"EnvProfile.preset_overrides = {self.preset_overrides!r}: expected "
                "{preset: {setting: value}}"
            )

    def params_class(self) -> Any:
        """The parameters class (None when the profile names none)."""
        return None if self.params is None else load_attr(self.params)


#: Profiles by registered id (what :func:`register` recorded).
_PROFILES: dict[str, EnvProfile] = {}
#: The profile of an env registered without one.
DEFAULT = EnvProfile()


def register(
    id: str, entry_point: Any, *, profile: EnvProfile | None = None, **kwargs: Any
) -> None:
    """:func:`gymnasium.register` (``kwargs``: its keywords, ``vector_entry_point`` among
    them) with the env's :class:`EnvProfile` recorded beside it. Registering an id twice keeps
    the first registration, as importing :mod:`tlshield` twice must."""
    if profile is not None and not isinstance(profile, EnvProfile):
        raise TypeError(f"register({id!r}): profile = {profile!r}: expected an EnvProfile")
    if id not in gym.registry:
        gym.register(id=id, entry_point=entry_point, **kwargs)
    _PROFILES.setdefault(id, profile or DEFAULT)


def profile_of(env_id: str) -> EnvProfile:
    """The profile registered with ``env_id`` (``"module:Env-v0"`` reads ``Env-v0``'s), or the
    default one for an env registered without a profile."""
    return _PROFILES.get(env_id.partition(":")[2] or env_id, DEFAULT)


def load_attr(path: str) -> Any:
    """The object ``"module:attr"`` names (the module imported on first use)."""
    module, _, attr = path.partition(":")
    return getattr(importlib.import_module(module), attr)
