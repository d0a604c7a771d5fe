"""The PPO presets and the CLF-bound schedules of training, as data (with the one function that
reads a schedule). The comments say why each preset value is what it is (docs/learning.md has
the measurements)."""

from __future__ import annotations

import math
from typing import Any

#: PPO updates of a training run (``tlshield train`` and ``tlshield reproduce``; 1,024 steps
#: each with the default preset). 600: with the progress reward's goal term, rl_cbf kept
#: 0.90-0.99 on the tuning seeds 0-4 at 600 updates and 0.87-0.96 at 300; rl_cbf_clf
#: 0.98-1.00 and 0.87-0.99 (docs/learning.md).
DEFAULT_UPDATES = 600
#: PPO updates of each run of a study of many runs: the ablation (docs/reproduction.md) and
#: each tuning sample, measured at this budget before the default grew to 600.
STUDY_UPDATES = 300
#: Evaluation episodes per trained policy (reset seeds from 10,000: never trained or tuned on).
DEFAULT_TRIALS = 100

#: PPO settings by preset: environments, SB3 PPO keywords and the networks, and tlshield's own
#: keys (read by :func:`tlshield.lab.training.train`): ``policy``
#: (:data:`tlshield.lab.policies.POLICIES`, default ``"gaussian"``), ``activation``
#: (``"ReLU"`` or ``"Tanh"``, default ``"ReLU"``), ``norm_obs`` / ``norm_reward`` (running
#: normalisation, default on), ``lr_schedule``, ``learn_from`` and the validation keys.
PRESETS: dict[str, dict[str, Any]] = {
    "paper": {
        "n_envs": 5,
        "ppo": {
            "n_steps": 200,
            "batch_size": 250,
            "n_epochs": 10,
            "learning_rate": 3e-4,
            "gamma": 0.99,
            "gae_lambda": 0.95,
            "clip_range": 0.2,
            "ent_coef": 0.0,
        },
        "net_arch": {"pi": [300, 200, 100], "vf": [300, 200, 100]},
    },
    "default": {
        "n_envs": 8,
        # The Gaussian's mean is tanh-bounded: SB3's unbounded mean drifted past the action
        # box, where clipping hides it, on the runs that collapsed (docs/learning.md).
        "policy": "tanh_mean",
        # The progress reward is bounded by design (Channel-v0: bands of width 7 per FSA state
        # with the goal term, a bonus of about 26), so it needs no running normalisation (the
        # goal term's runs were measured so); with it, a run whose returns stopped
        # varying divided by a tiny std, the value loss reached 1e3-1e4, and the global
        # gradient clip then starved the policy (approx_kl 1e-9): a permanent collapse.
        "norm_reward": False,
        # The learning rate decays linearly to 0 (without it the policy found the task and then
        # lost it again within the same run, measured).
        "lr_schedule": "linear",
        # PPO learns from the action it sampled (SB3's own; learn_from "sampled"). Learning
        # from the executed action without the CLF's part helped Channel-v0's tuning seeds but
        # not its fresh ones, and on PointMass-v0 it lost rl_cbf on 3 of 3 seeds, where this
        # preset finds it on 3 of 3 (docs/learning.md, "Learning at scale").
        "learn_from": "sampled",
        # Every 10 updates the deterministic policy runs 20 validation episodes (reset seeds
        # from tlshield.lab.seeds.validation_seed, never used for evaluation); the best checkpoint
        # is kept (the policy found the task and lost it again in some runs, measured).
        "validate_every": 10,
        "validation_trials": 20,
        "ppo": {
            "n_steps": 128,
            "batch_size": 512,
            "n_epochs": 10,
            # With raw rewards, 3e-4 left rl_cbf without a single success on 3 of 3 seeds;
            # 1e-3 (decaying linearly) found the task on 2 of 3 (docs/learning.md).
            "learning_rate": 1e-3,
            "gamma": 0.999,
            "gae_lambda": 0.95,
            # 0.2 let single updates undo what the policy had learned (measured: validation
            # success 0.85 -> 0 within 10 updates); 0.1 kept it rising.
            "clip_range": 0.1,
            "ent_coef": 0.0,
        },
        "net_arch": {"pi": [64, 64], "vf": [64, 64]},
    },
    # The FlatWorld benchmark's settings (tlshield.lab.benchmark), shared by every formula: SB3's
    # PPO defaults at a DeepLTL-sized batch, with raw observations and rewards (positions in
    # [-2, 2] and a bounded progress reward need no running statistics).
    "flatworld": {
        "n_envs": 8,
        "activation": "Tanh",
        "norm_obs": False,
        "norm_reward": False,
        "ppo": {
            "n_steps": 256,
            "batch_size": 256,
            "n_epochs": 10,
            "learning_rate": 3e-4,
            "gamma": 0.99,
            "gae_lambda": 0.95,
            "ent_coef": 0.0,
            "clip_range": 0.2,
        },
        "net_arch": {"pi": [64, 64], "vf": [64, 64]},
    },
    # Safety-Gymnasium's tasks (tlshield.lab.benchmark_safety_gym): Stable-Baselines3's PPO
    # defaults (one environment of 2048 steps per update, minibatches of 64, Tanh 64-64 networks,
    # raw observations and rewards), the settings the unshielded row of docs/guides/safety-gym.md
    # was measured with, the same for every configuration. Validation is on the return
    # (its profile is scored_by_return): 5 episodes of 1,000 steps every 10 updates (about 25%
    # more environment steps), the best checkpoint kept and the last one beside it.
    "safety-gym": {
        "n_envs": 1,
        "activation": "Tanh",
        "norm_obs": False,
        "norm_reward": False,
        "validate_every": 10,
        "validation_trials": 5,
        "ppo": {
            "n_steps": 2048,
            "batch_size": 64,
            "n_epochs": 10,
            "learning_rate": 3e-4,
            "gamma": 0.99,
            "gae_lambda": 0.95,
            "clip_range": 0.2,
            "ent_coef": 0.0,
        },
        "net_arch": {"pi": [64, 64], "vf": [64, 64]},
    },
}
#: The CLF-bound schedules of :func:`clf_scale` (the CLI and the tuner offer these).
SCHEDULES = ("fixed", "linear", "exponential")
#: The default schedule: the paper's fixed CLF bounds.
DEFAULT_SCHEDULE = SCHEDULES[0]
#: The default CLF bound scale at the end of a shrinking schedule.
DEFAULT_FINAL_SCALE = 0.2


def clf_scale(schedule: str, progress: float, final: float) -> float:
    """Scale of the CLF bounds at ``progress`` in [0, 1] of training (the paper's suggested
    improvement: trust the CLF less as the policy learns). ``final`` is the scale at the end."""
    if schedule == "fixed":
        return 1.0
    if schedule == "linear":
        return 1.0 + (final - 1.0) * progress
    if schedule == "exponential":
        return float(final**progress)
    raise ValueError(f"clf schedule {schedule!r}: expected one of {SCHEDULES}")


def updates_for(steps: int, preset: str) -> int:
    """The PPO updates of ``preset`` that cover ``steps`` environment steps (rounded up, as
    SB3's ``learn(total_timesteps=steps)`` does)."""
    spec = PRESETS[preset]
    return math.ceil(steps / (spec["n_envs"] * spec["ppo"]["n_steps"]))
