"""Named training settings: what ``tlshield train --settings FILE`` / ``--set NAME=VALUE`` and
``tlshield tune`` speak.

A setting is one of

* an environment constant (a field of the parameters class the env's profile names:
  :class:`tlshield.envs.ChannelParams`, ``PointMassParams`` for PointMass-v0 or
  ``FlatWorldParams`` for FlatWorld-v0, which also takes its task keyword ``formula``):
  ``c_r``, ``w``, ``alpha``, ``c3``, ``k``, ``clf_bounds``, ...; for a
  user's registered environment, any keyword of its factory (checked when it is built);
* a PPO setting (:data:`PPO_NAMES`): ``learning_rate``, ``ent_coef``, ``n_epochs``,
  ``batch_size``, ...;
* a training schedule (:data:`SCHEDULE_NAMES`): ``clf_schedule``, ``clf_final_scale``.

``gamma`` is PPO's discount; the environment's progress reward is sized for the same value.
A settings file is JSON: ``{"settings": {name: value, ...}}`` (what ``tune`` writes as
``best.json``, which also names its ``config``) or a bare ``{name: value}`` object. Names are
checked where they are given, against the list of known ones.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from tlshield._removed import refuse
from tlshield.envs import ENV_ID
from tlshield.envs.params import flat_names, from_flat, upgrade
from tlshield.envs.profile import profile_of
from tlshield.lab.runs import json_tuples

#: PPO settings a run accepts (SB3 ``PPO`` keywords, plus the number of environments, the
#: initial log standard deviation of the policy, the policy's kind (:data:`tlshield.lab.policies.
#: POLICIES`) and whether rewards are normalised). ``use_sde`` (generalized state-dependent
#: exploration) needs ``policy: "gaussian"``, SB3's own policy; ``learn_from`` chooses the action
#: PPO learns from (:data:`tlshield.lab.training.LEARN_FROM`); ``lr_schedule`` and
#: ``ent_schedule`` hold or decay the learning rate and ``ent_coef``
#: (:data:`tlshield.lab.training.LR_SCHEDULES`).
PPO_NAMES = (
    "learning_rate",
    "ent_coef",
    "n_epochs",
    "batch_size",
    "n_steps",
    "n_envs",
    "gamma",
    "gae_lambda",
    "clip_range",
    "vf_coef",
    "max_grad_norm",
    "log_std_init",
    "policy",
    "norm_reward",
    "use_sde",
    "sde_sample_freq",
    "learn_from",
    "lr_schedule",
    "ent_schedule",
)
#: Settings of :func:`tlshield.lab.training.train` itself.
SCHEDULE_NAMES = ("clf_schedule", "clf_final_scale")


def env_names(env_id: str = ENV_ID) -> tuple[str, ...]:
    """The environment constants of ``env_id`` (its parameters' flat names; empty for a
    user's environment, whose keywords its own factory checks)."""
    cls = _params_class(env_id)
    if cls is None:
        return ()
    return (*flat_names(cls), *profile_of(env_id).task_keywords)


def known_names(env_id: str = ENV_ID) -> tuple[str, ...]:
    """Every setting name ``env_id``'s runs accept, sorted."""
    return tuple(sorted({*env_names(env_id), *PPO_NAMES, *SCHEDULE_NAMES}))


def check_names(names: Any, env_id: str = ENV_ID, where: str = "settings") -> None:
    """Raises ValueError naming the unknown settings in ``names`` and listing the known ones."""
    if _params_class(env_id) is None:  # a user's env: its factory checks its own keywords
        return
    known = known_names(env_id)
    unknown = sorted(str(n) for n in names if n not in known)
    if unknown:
        raise ValueError(
            f"{where}: unknown setting(s) {', '.join(unknown)} for {env_id}; known: "
            f"{', '.join(known)}"
        )


def split(settings: dict[str, Any], env_id: str = ENV_ID) -> dict[str, Any]:
    """Keyword arguments of :func:`tlshield.lab.training.train` for ``settings``: the schedule
    settings as themselves, the PPO ones under ``ppo``, the rest as environment overrides.
    Checks the names, and the environment constants by building the environment's config."""
    settings = upgrade(settings, "settings")
    check_names(settings, env_id)
    out: dict[str, Any] = {k: settings[k] for k in SCHEDULE_NAMES if k in settings}
    ppo = {k: settings[k] for k in PPO_NAMES if k in settings}
    if ppo:
        out["ppo"] = ppo
    env = {k: json_tuples(v) for k, v in settings.items() if k not in PPO_NAMES + SCHEDULE_NAMES}
    cls = _params_class(env_id)
    if cls is not None:
        # FlatWorld's task is a keyword of its factory, not a constant of its config.
        task = profile_of(env_id).task_keywords
        constants = {k: v for k, v in env.items() if k not in task}
        try:
            from_flat(cls, constants).check()
        except (TypeError, ValueError) as err:
            raise ValueError(f"settings: {err}") from None
    return {**out, **env}


def load(path: str | Path) -> tuple[dict[str, Any], str | None]:
    """The settings of a JSON file and the configuration it names (``None`` if it names none).
    Raises ValueError on a file that is not a JSON object of settings."""
    try:
        data = json.loads(Path(path).read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: not JSON ({err})") from None
    settings = data.get("settings", data) if isinstance(data, dict) else None
    if not isinstance(settings, dict):
        raise ValueError(f"{path}: expected a JSON object of settings, {{name: value}}")
    config = data.get("config") if "settings" in data else None
    settings = upgrade(settings, str(path), from_file=True)
    check_names(settings, data.get("env_id", ENV_ID), where=str(path))
    return settings, config


def parse_assignments(items: list[str], env_id: str = ENV_ID) -> dict[str, Any]:
    """``["alpha=3", "clf_schedule=linear", "clf_bounds=[[-0.2,-0.4],[0.2,0.4]]"]`` -> a
    settings dict; values are JSON, or plain strings when they are not."""
    out: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name:
            raise ValueError(f"--set {item!r}: expected NAME=VALUE")
        try:
            out[name.strip()] = json.loads(text)
        except json.JSONDecodeError:
            out[name.strip()] = text
    out = upgrade(out, "--set")
    check_names(out, env_id, where="--set")
    return out


def _params_class(env_id: str) -> Any:
    """The parameters class its profile names (:mod:`tlshield.envs.profile`); None for an env
    whose profile names none (an unregistered id is an error)."""
    from tlshield.lab.envs import check_env_id

    check_env_id(env_id)
    return profile_of(env_id).params_class()


#: Names removed in 0.4, refused with a message naming what replaced them.
__getattr__ = refuse(__name__, {"TASK_KEYWORDS": "tlshield.envs.profile_of(env_id).task_keywords"})
