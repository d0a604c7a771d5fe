"""Environments and tasks of tlshield (the paper's channel case study)."""

from tlshield.envs.channel import STATE_DIM, TASK, channel_task_spec

__all__ = ["STATE_DIM", "TASK", "channel_task_spec"]
