"""Where one PPO update's time goes (docs/learning.md): rollout (the vector env's step, the
policy's forward pass, the per-step metrics, the executed actions), gradient steps,
validation and logging.

    .venv/bin/python scripts/profile_update.py --updates 30 [--set n_envs=64 --set batch_size=2048]

Trains ``tlshield/Channel-v0`` (rl_cbf_clf, seed 0, the default preset with the ``--set``
settings on top) with timers around the methods that do each part, and prints milliseconds per
update and shares of the training's wall time. Timers add a few microseconds per call; nothing
else changes.
"""

from __future__ import annotations

import argparse
import functools
import tempfile
import time
from collections import defaultdict
from typing import Any

TOTALS: dict[str, float] = defaultdict(float)


def timed(cls: type, name: str, label: str) -> None:
    """Wraps ``cls.name`` so that its wall time adds to ``TOTALS[label]``."""
    original = getattr(cls, name)

    @functools.wraps(original)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            TOTALS[label] += time.perf_counter() - start

    setattr(cls, name, wrapper)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--updates", type=int, default=30)
    parser.add_argument("--config", default="rl_cbf_clf")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    args = parser.parse_args()
    from stable_baselines3 import PPO
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
    from stable_baselines3.common.policies import ActorCriticPolicy
    from stable_baselines3.common.vec_env import VecNormalize

    from tlshield.lab import settings
    from tlshield.lab.callbacks import ExecutedActions, UpdateLog, Validation
    from tlshield.lab.training import train
    from tlshield.sb3 import WorldVecEnv

    timed(OnPolicyAlgorithm, "collect_rollouts", "rollout (all)")
    timed(WorldVecEnv, "step_wait", "env step (core batch + infos)")
    timed(VecNormalize, "step_wait", "env step + normalisation")
    timed(ActorCriticPolicy, "forward", "policy forward")
    timed(UpdateLog, "_on_step", "per-step metrics")
    timed(ExecutedActions, "_on_step", "executed actions")
    timed(ExecutedActions, "_on_rollout_end", "executed actions")
    timed(PPO, "train", "gradient steps (PPO.train)")
    timed(Validation, "_validate", "validation")
    timed(UpdateLog, "_on_rollout_end", "update end (logging)")
    options = settings.split(settings.parse_assignments(args.set))
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        folder = train(args.config, 0, args.updates, out, progress=False, **options)
        wall = time.perf_counter() - start
        n_envs = int(__import__("json").loads((folder / "run.json").read_text())["n_envs"])
    learn = TOTALS["rollout (all)"] + TOTALS["gradient steps (PPO.train)"]
    rows = [
        ("rollout (all)", TOTALS["rollout (all)"]),
        ("- env step (core batch + infos)", TOTALS["env step (core batch + infos)"]),
        (
            "- VecNormalize",
            TOTALS["env step + normalisation"] - TOTALS["env step (core batch + infos)"],
        ),
        ("- policy forward", TOTALS["policy forward"]),
        ("- per-step metrics (callback)", TOTALS["per-step metrics"]),
        ("- executed actions (callback)", TOTALS["executed actions"]),
        ("- validation", TOTALS["validation"]),
        ("- logging", TOTALS["update end (logging)"]),
        ("gradient steps (PPO.train)", TOTALS["gradient steps (PPO.train)"]),
    ]
    parts = sum(seconds for label, seconds in rows[1:-1])
    rows.insert(-1, ("- SB3's own (buffer, tensors, callbacks' calls)", rows[0][1] - parts))
    print(f"settings: {args.set or 'default'}; {args.updates} updates, {n_envs} envs")
    print(f"train() wall {wall:.1f} s (rollouts + gradient steps {learn:.1f} s)\n")
    print("| part | ms per update | share of rollouts + gradient steps |")
    print("|---|---:|---:|")
    for label, seconds in rows:
        print(f"| {label} | {1e3 * seconds / args.updates:.1f} | {seconds / learn:.0%} |")


if __name__ == "__main__":
    main()
