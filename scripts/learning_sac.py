"""SAC (Stable-Baselines3) on Channel-v0's core vector env: one of the levers of
docs/learning.md, measured beside PPO on the same environments, seeds and evaluation.

    .venv/bin/python scripts/learning_sac.py --out results_learning/sac \\
        --configs rl_cbf_clf rl_cbf --seeds 0 1 2 --steps 100000

Per (config, seed): SAC trains on ``n_envs`` environments (reset seeds
:func:`tlshield.lab.seeds.train_seed`, observations normalised as PPO's are), validates the
deterministic policy every ``--validate-every`` steps on 20 episodes (reset seeds
:func:`tlshield.lab.seeds.validation_seed`) and keeps the best, then evaluates the kept and the
last policy on the 100 evaluation trials PPO's runs are evaluated on
(:data:`tlshield.lab.evaluation.EVAL_SEED`). Prints, and writes to ``OUT/sac.md``, the rows of
:func:`tlshield.lab.report.seeds_table`'s columns, and the wall time. One run at a time: start two
processes for two cores.
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np


def run(config: str, seed: int, args: argparse.Namespace) -> dict[str, Any]:
    """Trains and evaluates one (config, seed); returns its row."""
    import torch
    from stable_baselines3 import SAC
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import VecNormalize

    from tlshield.envs import ENV_ID
    from tlshield.lab.callbacks import UpdateMetrics
    from tlshield.lab.evaluation import EVAL_SEED, rollouts
    from tlshield.lab.seeds import train_seed, validation_seed
    from tlshield.sb3 import make_vec_env

    torch.set_num_threads(1)
    gamma = 0.999
    overrides = {"gamma": gamma}
    venv = VecNormalize(
        make_vec_env(ENV_ID, args.n_envs, config, seed=train_seed(seed), **overrides),
        norm_reward=False,
        gamma=gamma,
    )
    model = SAC(
        "MlpPolicy",
        venv,
        seed=seed,
        device="cpu",
        gamma=gamma,
        batch_size=256,
        learning_starts=1000,
        train_freq=1,
        gradient_steps=args.gradient_steps,
        policy_kwargs={"net_arch": [64, 64]},
        verbose=0,
    )

    def success(policy: Any, norm: Any, seeds: list[int]) -> float:
        def act(obs: np.ndarray) -> np.ndarray:
            return policy.predict(norm.normalize_obs(obs), deterministic=True)[0]

        outcomes = rollouts(config, overrides, act, seeds)
        return sum(o["success"] for o in outcomes) / len(seeds)

    class Track(BaseCallback):  # type: ignore[misc]
        def __init__(self) -> None:
            super().__init__()
            self.metrics = UpdateMetrics(args.n_envs, gamma)
            self.best, self.validations = -1.0, []
            self.kept: tuple[Any, Any, int] | None = None

        def _on_step(self) -> bool:
            self.metrics.step(
                venv.get_original_reward(), self.locals["dones"], self.locals["infos"]
            )
            if self.num_timesteps % args.validate_every < args.n_envs:
                seeds = [validation_seed(seed, k) for k in range(20)]
                value = success(self.model, venv, seeds)
                self.validations.append(value)
                if value >= self.best:
                    self.best = value
                    self.kept = (
                        copy.deepcopy(self.model.policy),
                        copy.deepcopy(venv.obs_rms),
                        self.num_timesteps,
                    )
            return True

    track = Track()
    start = time.perf_counter()
    model.learn(total_timesteps=args.steps, callback=track)
    wall = time.perf_counter() - start
    trials = [EVAL_SEED + k for k in range(args.trials)]
    last = success(model, venv, trials)
    kept_policy, kept_rms, kept_at = track.kept if track.kept else (model.policy, venv.obs_rms, -1)
    live_rms, venv.obs_rms = venv.obs_rms, kept_rms
    kept = success(kept_policy, venv, trials)
    venv.obs_rms = live_rms
    val = track.validations
    return {
        "config": config,
        "seed": seed,
        "kept": kept,
        "last": last,
        "best_val": max(val) if val else math.nan,
        "last_val": val[-1] if val else math.nan,
        "kept_step": kept_at,
        "violations": track.metrics.violations,
        "wall_s": wall,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="results_learning/sac")
    parser.add_argument("--configs", nargs="+", default=["rl_cbf_clf", "rl_cbf"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--n-envs", type=int, default=8)
    parser.add_argument("--gradient-steps", type=int, default=1)
    parser.add_argument("--validate-every", type=int, default=10_240)
    parser.add_argument("--trials", type=int, default=100)
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for config in args.configs:
        for seed in args.seeds:
            path = out / f"{config}_s{seed}.json"
            if not path.is_file():  # finished runs are kept: an interrupted sweep resumes
                path.write_text(json.dumps(run(config, seed, args)))
            rows.append(json.loads(path.read_text()))
    lines = [
        "| config | seed | eval kept | eval last | best val | last val | kept at step | "
        "train violations | wall s |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['config']} | {r['seed']} | {r['kept']:.2f} | {r['last']:.2f} | "
            f"{r['best_val']:.2f} | {r['last_val']:.2f} | {r['kept_step']} | "
            f"{r['violations']} | {r['wall_s']:.0f} |"
        )
    text = "\n".join(lines)
    (out / "sac.md").write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
