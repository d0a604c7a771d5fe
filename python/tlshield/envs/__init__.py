"""Environments and tasks of tlshield, registered with Gymnasium when ``tlshield`` is
imported: the paper's channel case study ``tlshield/Channel-v0``, a double-integrator robot
with a sequencing task, ``tlshield/PointMass-v0``, and DeepLTL's benchmark with any formula over
its colours, ``tlshield/FlatWorld-v0``."""

from typing import Any

import gymnasium as gym

from tlshield.envs.channel import (
    CONFIGS,
    STATE_DIM,
    TASK,
    ChannelConfig,
    ChannelEnv,
    channel_shield,
    channel_task_spec,
)

ENV_ID = "tlshield/Channel-v0"
POINT_MASS_ID = "tlshield/PointMass-v0"
FLATWORLD_ID = "tlshield/FlatWorld-v0"

if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point="tlshield.envs.channel:ChannelEnv")
if POINT_MASS_ID not in gym.registry:
    gym.register(id=POINT_MASS_ID, entry_point="tlshield.envs.point_mass:make_point_mass")
if FLATWORLD_ID not in gym.registry:
    gym.register(id=FLATWORLD_ID, entry_point="tlshield.envs.flatworld:make_flatworld")


def check_env_id(env_id: str) -> None:
    """Raises ValueError unless ``env_id`` is a registered Gymnasium id."""
    if env_id not in gym.registry:
        tlshield_ids = sorted(k for k in gym.registry if k.startswith("tlshield/"))
        raise ValueError(
            f"env {env_id!r}: not a registered Gymnasium id (register your environment with "
            f"gymnasium.register first; bundled: {', '.join(tlshield_ids)})"
        )


def make(env_id: str, config: str, **kwargs: Any) -> gym.Env:
    """One environment of ``env_id`` in shield configuration ``config``: Channel-v0 unwrapped
    (training and evaluation read its ``state`` directly), any other through ``gym.make``."""
    if env_id == ENV_ID:
        return ChannelEnv(config=config, **kwargs)
    return gym.make(env_id, config=config, **kwargs)


__all__ = [
    "CONFIGS",
    "ENV_ID",
    "FLATWORLD_ID",
    "POINT_MASS_ID",
    "STATE_DIM",
    "TASK",
    "ChannelConfig",
    "ChannelEnv",
    "channel_shield",
    "channel_task_spec",
    "check_env_id",
    "make",
]
