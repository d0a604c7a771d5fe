"""Environments and tasks of tlshield, registered with Gymnasium when ``tlshield`` is
imported: the paper's channel case study ``tlshield/Channel-v0``, a double-integrator robot
with a sequencing task, ``tlshield/PointMass-v0``, and DeepLTL's benchmark with any formula over
its colours, ``tlshield/FlatWorld-v0``."""

from tlshield.envs.channel import (
    CONFIGS,
    PAPER_ENV,
    STATE_DIM,
    TASK,
    ChannelEnv,
    ChannelParams,
    channel_shield,
    channel_task_spec,
)
from tlshield.envs.profile import EnvProfile, profile_of, register

ENV_ID = "tlshield/Channel-v0"
POINT_MASS_ID = "tlshield/PointMass-v0"
FLATWORLD_ID = "tlshield/FlatWorld-v0"

register(
    ENV_ID,
    "tlshield.envs.channel:ChannelEnv",
    vector_entry_point="tlshield.vector:ChannelVectorEnv",
    profile=EnvProfile(
        params="tlshield.envs.channel:ChannelParams",
        recorder="tlshield.envs.channel_paths:ChannelPaths",
        clf_shield="tlshield.envs.channel:channel_shield",
        preset_overrides={"paper": PAPER_ENV},
    ),
)
register(
    POINT_MASS_ID,
    "tlshield.envs.point_mass:make_point_mass",
    vector_entry_point="tlshield.vector:PointMassVectorEnv",
    profile=EnvProfile(params="tlshield.envs.point_mass:PointMassParams"),
)
register(
    FLATWORLD_ID,
    "tlshield.envs.flatworld:make_flatworld",
    vector_entry_point="tlshield.vector:flatworld_vector_env",
    profile=EnvProfile(
        params="tlshield.envs.flatworld:FlatWorldParams", task_keywords=("formula",)
    ),
)
#: Safety-Gymnasium's tasks, shielded (``make safety-gym`` installs their stack; registering
#: imports none of it). Scored by their return and cost.
SAFETY_GYM_IDS = (
    "tlshield/SafetyPointGoal1-v0",
    "tlshield/SafetyPointGoal2-v0",
    "tlshield/SafetyCarGoal1-v0",
)
for _id in SAFETY_GYM_IDS:
    register(
        _id,
        "tlshield.envs.safety_gym:make_safety_goal",
        vector_entry_point="tlshield.vector:safety_goal_vector_env",
        kwargs={"task": _id.removeprefix("tlshield/")},
        profile=EnvProfile(scored_by_return=True),
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
    "EnvProfile",
    "channel_shield",
    "channel_task_spec",
    "profile_of",
    "register",
]
