"""Environments and tasks of tlshield, registered with Gymnasium when ``tlshield`` is
imported: the paper's channel case study ``tlshield/Channel-v0``, a double-integrator robot
with a sequencing task, ``tlshield/PointMass-v0``, and DeepLTL's benchmark with any formula over
its colours, ``tlshield/FlatWorld-v0``."""

import gymnasium as gym

from tlshield.envs.channel import (
    CONFIGS,
    STATE_DIM,
    TASK,
    ChannelEnv,
    ChannelParams,
    channel_shield,
    channel_task_spec,
)

ENV_ID = "tlshield/Channel-v0"
POINT_MASS_ID = "tlshield/PointMass-v0"
FLATWORLD_ID = "tlshield/FlatWorld-v0"

if ENV_ID not in gym.registry:
    gym.register(
        id=ENV_ID,
        entry_point="tlshield.envs.channel:ChannelEnv",
        vector_entry_point="tlshield.vector:ChannelVectorEnv",
    )
if POINT_MASS_ID not in gym.registry:
    gym.register(
        id=POINT_MASS_ID,
        entry_point="tlshield.envs.point_mass:make_point_mass",
        vector_entry_point="tlshield.vector:PointMassVectorEnv",
    )
if FLATWORLD_ID not in gym.registry:
    gym.register(
        id=FLATWORLD_ID,
        entry_point="tlshield.envs.flatworld:make_flatworld",
        vector_entry_point="tlshield.vector:flatworld_vector_env",
    )
#: Safety-Gymnasium's tasks, shielded (``make safety-gym`` installs their stack; registering
#: imports none of it).
SAFETY_GYM_IDS = (
    "tlshield/SafetyPointGoal1-v0",
    "tlshield/SafetyPointGoal2-v0",
    "tlshield/SafetyCarGoal1-v0",
)
for _id in SAFETY_GYM_IDS:
    if _id not in gym.registry:
        gym.register(
            id=_id,
            entry_point="tlshield.envs.safety_gym:make_safety_goal",
            vector_entry_point="tlshield.vector:safety_goal_vector_env",
            kwargs={"task": _id.removeprefix("tlshield/")},
        )


__all__ = [
    "CONFIGS",
    "ENV_ID",
    "FLATWORLD_ID",
    "POINT_MASS_ID",
    "SAFETY_GYM_IDS",
    "STATE_DIM",
    "TASK",
    "ChannelEnv",
    "ChannelParams",
    "channel_shield",
    "channel_task_spec",
]
