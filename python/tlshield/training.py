"""PPO on tlshield/Channel-v0 (Stable-Baselines3), per-update metrics, evaluation.

A run folder holds ``config.json`` (what it ran with), ``metrics.csv`` (one row per update,
written as it goes, so an interrupted run stays readable), ``tb/`` (TensorBoard), ``model.zip``
and, after :func:`evaluate`, ``evaluation.json`` and ``trajectories.npz``.

PPO (documented choices; the paper fixes the networks and the batch): separate policy and value
MLPs 300-200-100 with ReLU; 5 environments x 200 steps = 1000 steps (5 trajectories of the
horizon) per update; 10 epochs of minibatches of 250; Adam 3e-4; gamma 0.99, GAE lambda 0.95;
clip 0.2; no entropy bonus; CPU, one torch thread (deterministic for a seed). Observations and
rewards are normalised by running statistics (SB3 ``VecNormalize``, saved as
``vecnormalize.pkl`` and used by :func:`evaluate`); the metrics are in raw units.
"""

from __future__ import annotations

import csv
import json
import math
import time
from collections.abc import Callable
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np

from tlshield.envs.channel import CONFIGS, STATE_DIM, ChannelConfig, ChannelEnv, channel_shield

#: Columns of metrics.csv, in order.
METRIC_COLUMNS = (
    "update",
    "timesteps",
    "episodes",
    "return_mean",
    "return_std",
    "min_h_c1",
    "min_h_c2",
    "min_obstacle_distance",
    "violations",
    "trap_entries",
    "successes",
    "relaxed",
    "failed",
    "clf_scale",
    "wall_time",
)

N_ENVS = 5
N_STEPS = 200
PPO_KWARGS: dict[str, Any] = {
    "n_steps": N_STEPS,
    "batch_size": 250,
    "n_epochs": 10,
    "learning_rate": 3e-4,
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "clip_range": 0.2,
    "ent_coef": 0.0,
}
NET_ARCH = {"pi": [300, 200, 100], "vf": [300, 200, 100]}
SCHEDULES = ("fixed", "linear", "exponential")


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


def _scaled(cfg: ChannelConfig, scale: float) -> ChannelConfig:
    (lo_v, lo_w), (hi_v, hi_w) = cfg.clf_bounds
    return replace(
        cfg,
        clf_bounds=((lo_v * scale, lo_w * scale), (hi_v * scale, hi_w * scale)),
    )


def _check_run_args(config: str, updates: int, schedule: str, final_scale: float) -> None:
    if config not in CONFIGS:
        raise ValueError(f"config {config!r}: expected one of {', '.join(CONFIGS)}")
    if not (isinstance(updates, int) and updates > 0):
        raise ValueError(f"updates = {updates!r}: expected a positive integer")
    if schedule not in SCHEDULES:
        raise ValueError(f"clf schedule {schedule!r}: expected one of {', '.join(SCHEDULES)}")
    if not (0.0 < final_scale <= 1.0):
        raise ValueError(f"final CLF scale {final_scale!r}: expected a number in (0, 1]")


def make_vec_env(config: str, seed: int, overrides: dict[str, Any]) -> tuple[Any, Any]:
    """The training VecEnv (shielded in one batch call when the config has a shield) and the
    ShieldedVecEnv wrapper (or None)."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    from tlshield.wrappers import ShieldedVecEnv

    has_shield = any(CONFIGS[config])
    venv = DummyVecEnv(
        [
            (lambda: ChannelEnv(config=config, shield_in_env=not has_shield, **overrides))
            for _ in range(N_ENVS)
        ]
    )
    venv.seed(seed)
    if not has_shield:
        return venv, None
    template = venv.envs[0]
    wrapper = ShieldedVecEnv(venv, template.shield, action_fn=template.rl_action)
    return wrapper, wrapper


class _Metrics:
    """Accumulates one update's statistics from the step infos."""

    def __init__(self, n_envs: int, gamma: float) -> None:
        self.gamma = gamma
        self.discounted = np.zeros(n_envs)
        self.discount = np.ones(n_envs)
        self.was_trapped = np.zeros(n_envs, dtype=bool)
        self.reset_update()

    def reset_update(self) -> None:
        self.returns: list[float] = []
        self.min_h = [math.inf, math.inf]
        self.min_d = math.inf
        self.violations = self.trap_entries = self.successes = 0
        self.relaxed = self.failed = 0

    def step(self, rewards: np.ndarray, dones: np.ndarray, infos: list[dict[str, Any]]) -> None:
        self.discounted += self.discount * rewards
        self.discount *= self.gamma
        for i, info in enumerate(infos):
            h = info["constraints"]
            self.min_h[0] = min(self.min_h[0], h["c1"])
            self.min_h[1] = min(self.min_h[1], h["c2"])
            self.min_d = min(self.min_d, info["min_obstacle_distance"])
            self.violations += info["violation"]
            self.trap_entries += info["trap"] and not self.was_trapped[i]
            self.was_trapped[i] = info["trap"]
            self.successes += info["success"]
            status = info["shield"]["status"]
            self.relaxed += status == "relaxed"
            self.failed += status == "failed"
            if dones[i]:
                self.returns.append(float(self.discounted[i]))
                self.discounted[i], self.discount[i] = 0.0, 1.0
                self.was_trapped[i] = False


def train(
    config: str,
    seed: int,
    updates: int,
    out: str | Path,
    *,
    clf_schedule: str = "fixed",
    clf_final_scale: float = 0.2,
    progress: bool = True,
    **overrides: Any,
) -> Path:
    """Trains PPO on one configuration; returns the run folder. Ctrl-C stops cleanly: the
    metrics so far and the model are kept (``config.json`` then says ``"interrupted": true``)."""
    _check_run_args(config, updates, clf_schedule, clf_final_scale)
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.logger import configure

    torch.set_num_threads(1)
    run = Path(out)
    run.mkdir(parents=True, exist_ok=True)
    from stable_baselines3.common.vec_env import VecNormalize

    inner, shielded = make_vec_env(config, seed, overrides)
    cfg: ChannelConfig = inner.get_attr("cfg", [0])[0]
    venv = VecNormalize(inner, norm_obs=True, norm_reward=True, gamma=PPO_KWARGS["gamma"])
    record = {
        "config": config,
        "seed": seed,
        "updates": updates,
        "clf_schedule": clf_schedule,
        "clf_final_scale": clf_final_scale,
        "n_envs": N_ENVS,
        "ppo": {**PPO_KWARGS, "net_arch": NET_ARCH, "activation": "ReLU"},
        "env": asdict(cfg),
        "overrides": overrides,
        "interrupted": False,
        "finished": False,
    }
    (run / "config.json").write_text(json.dumps(record, indent=2))

    model = PPO(
        "MlpPolicy",
        venv,
        seed=seed,
        device="cpu",
        verbose=0,
        policy_kwargs={"net_arch": NET_ARCH, "activation_fn": torch.nn.ReLU},
        **PPO_KWARGS,
    )
    model.set_logger(configure(str(run / "tb"), ["tensorboard"]))
    metrics = _Metrics(N_ENVS, PPO_KWARGS["gamma"])
    csv_file = (run / "metrics.csv").open("w", newline="")
    writer = csv.DictWriter(csv_file, fieldnames=METRIC_COLUMNS)
    writer.writeheader()
    csv_file.flush()
    start = time.perf_counter()
    bar = _progress_bar(updates, f"{config} seed {seed}", progress)

    class Callback(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.update = 0
            self.scale = 1.0

        def _on_rollout_start(self) -> None:
            self.scale = clf_scale(clf_schedule, self.update / max(updates - 1, 1), clf_final_scale)
            if shielded is not None and CONFIGS[config][1] and clf_schedule != "fixed":
                shielded.shield = channel_shield(_scaled(cfg, self.scale), config)

        def _on_step(self) -> bool:
            raw = venv.get_original_reward()  # metrics in raw units, not normalised
            metrics.step(raw, self.locals["dones"], self.locals["infos"])
            return True

        def _on_rollout_end(self) -> None:
            self.update += 1
            returns = metrics.returns
            row = {
                "update": self.update,
                "timesteps": self.num_timesteps,
                "episodes": len(returns),
                "return_mean": float(np.mean(returns)) if returns else math.nan,
                "return_std": float(np.std(returns)) if returns else math.nan,
                "min_h_c1": metrics.min_h[0],
                "min_h_c2": metrics.min_h[1],
                "min_obstacle_distance": metrics.min_d,
                "violations": metrics.violations,
                "trap_entries": metrics.trap_entries,
                "successes": metrics.successes,
                "relaxed": metrics.relaxed,
                "failed": metrics.failed,
                "clf_scale": self.scale,
                "wall_time": time.perf_counter() - start,
            }
            writer.writerow(row)
            csv_file.flush()
            for key, value in row.items():
                if key not in ("update", "timesteps"):
                    self.logger.record(f"tlshield/{key}", value)
            metrics.reset_update()
            bar.update(1)
            bar.set_postfix(ret=f"{row['return_mean']:.1f}", viol=row["violations"])

    try:
        model.learn(total_timesteps=updates * N_ENVS * N_STEPS, callback=Callback())
        record["finished"] = True
    except KeyboardInterrupt:
        record["interrupted"] = True
    finally:
        bar.close()
        csv_file.close()
        model.save(run / "model.zip")
        venv.save(str(run / "vecnormalize.pkl"))
        record["wall_time"] = time.perf_counter() - start
        (run / "config.json").write_text(json.dumps(record, indent=2))
        venv.close()
    if record["interrupted"]:
        raise KeyboardInterrupt
    return run


def _progress_bar(total: int, desc: str, enabled: bool) -> Any:
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit="update", disable=not enabled, leave=False)


def load_run(run: str | Path) -> dict[str, Any]:
    """The run's config.json (raises FileNotFoundError with a clear message)."""
    path = Path(run) / "config.json"
    if not path.is_file():
        raise FileNotFoundError(f"{run}: not a tlshield run folder (no config.json)")
    return json.loads(path.read_text())


def evaluate(
    run: str | Path,
    trials: int = 20,
    seed: int = 10_000,
    policy: Callable[[np.ndarray], np.ndarray] | None = None,
) -> dict[str, Any]:
    """The paper's evaluation of a trained run: CBF always on; an episode ends at the horizon,
    on success or on collision. Writes evaluation.json and trajectories.npz into the run."""
    if not (isinstance(trials, int) and trials > 0):
        raise ValueError(f"trials = {trials!r}: expected a positive integer")
    record = load_run(run)
    if policy is None:
        model_path = Path(run) / "model.zip"
        if not model_path.is_file():
            raise FileNotFoundError(f"{run}: no model.zip (training did not finish?)")
        import pickle

        from stable_baselines3 import PPO

        model = PPO.load(model_path, device="cpu")
        stats_path = Path(run) / "vecnormalize.pkl"
        normalize: Callable[[np.ndarray], np.ndarray] = lambda obs: obs  # noqa: E731
        if stats_path.is_file():
            with stats_path.open("rb") as f:
                stats = pickle.load(f)
            normalize = stats.normalize_obs

        def policy(obs: np.ndarray) -> np.ndarray:
            return model.predict(normalize(obs), deterministic=True)[0]

    env = ChannelEnv(config=record["config"], evaluation=True, **record.get("overrides", {}))
    successes = collisions = violation_steps = violating_trials = 0
    steps_to_success: list[int] = []
    paths: list[np.ndarray] = []
    starts: list[np.ndarray] = []
    for trial in range(trials):
        obs, _ = env.reset(seed=seed + trial)
        starts.append(obs[:STATE_DIM].copy())
        path = [obs[:2].copy()]
        violated = False
        for t in range(env.cfg.horizon):
            obs, _, terminated, truncated, info = env.step(policy(obs))
            path.append(obs[:2].copy())
            violation_steps += info["violation"]
            violated |= info["violation"]
            if terminated or truncated:
                successes += info["success"]
                collisions += info["collision"]
                if info["success"]:
                    steps_to_success.append(t + 1)
                break
        violating_trials += violated
        paths.append(np.array(path))
    result = {
        "config": record["config"],
        "seed": record["seed"],
        "trials": trials,
        "eval_seed": seed,
        "success_rate": successes / trials,
        "successes": successes,
        "collisions": collisions,
        "violation_steps": violation_steps,
        "violating_trials": violating_trials,
        "mean_steps_to_success": float(np.mean(steps_to_success)) if steps_to_success else None,
    }
    Path(run, "evaluation.json").write_text(json.dumps(result, indent=2))
    np.savez_compressed(
        Path(run, "trajectories.npz"),
        starts=np.array(starts),
        lengths=np.array([len(p) for p in paths]),
        paths=np.concatenate(paths),
    )
    return result


def _run_one(job: tuple[str, int, int, str, int, dict[str, Any]]) -> str:
    """One (config, seed) of a reproduction: train, then evaluate (a worker process)."""
    config, seed, updates, folder, trials, options = job
    train(config, seed, updates, folder, progress=False, **options)
    evaluate(folder, trials=trials)
    return folder


def reproduce(
    out: str | Path,
    *,
    configs: tuple[str, ...] = tuple(CONFIGS),
    seeds: tuple[int, ...] = (0, 1),
    updates: int = 150,
    trials: int = 20,
    workers: int = 2,
    progress: bool = True,
    **options: Any,
) -> Path:
    """Trains and evaluates every configuration x seed (``workers`` processes), then writes the
    figures (``out/figures``) and the results table (``out/results.md``). Runs that already
    finished and were evaluated (same folder) are kept, so an interrupted reproduction resumes."""
    for config in configs:
        _check_run_args(
            config,
            updates,
            options.get("clf_schedule", "fixed"),
            options.get("clf_final_scale", 0.2),
        )
    if not (isinstance(trials, int) and trials > 0):
        raise ValueError(f"trials = {trials!r}: expected a positive integer")
    root = Path(out)
    root.mkdir(parents=True, exist_ok=True)
    jobs = []
    for config in configs:
        for seed in seeds:
            folder = root / f"{config}_s{seed}"
            done = (folder / "evaluation.json").is_file() and _finished(folder, updates)
            if not done:
                jobs.append((config, seed, updates, str(folder), trials, options))
    bar = _progress_bar(len(jobs), "runs", progress)
    try:
        if workers > 1 and len(jobs) > 1:
            import multiprocessing as mp

            with mp.get_context("spawn").Pool(min(workers, len(jobs))) as pool:
                for _ in pool.imap_unordered(_run_one, jobs):
                    bar.update(1)
        else:
            for job in jobs:
                _run_one(job)
                bar.update(1)
    finally:
        bar.close()
    from tlshield.plots import plot_all, results_table

    plot_all(root)
    (root / "results.md").write_text(results_table(root) + "\n")
    return root


def _finished(folder: Path, updates: int) -> bool:
    try:
        record = load_run(folder)
    except FileNotFoundError:
        return False
    return bool(record.get("finished")) and record.get("updates") == updates
