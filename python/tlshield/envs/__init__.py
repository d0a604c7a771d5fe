"""Environments and tasks of tlshield: the paper's channel case study, registered with
Gymnasium as ``tlshield/Channel-v0`` when ``tlshield`` is imported."""

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

if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point="tlshield.envs.channel:ChannelEnv")

__all__ = [
    "CONFIGS",
    "ENV_ID",
    "STATE_DIM",
    "TASK",
    "ChannelConfig",
    "ChannelEnv",
    "channel_shield",
    "channel_task_spec",
]
