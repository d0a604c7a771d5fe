"""PPO on tlshield/Channel-v0 (Stable-Baselines3) with per-update metrics; the reproduction
and the ablation of the README (training, then :func:`tlshield.evaluation.evaluate`).

A run folder (schema and loaders: :mod:`tlshield.runs`) holds ``config.json`` (what it ran
with, and which checkpoint was kept), ``metrics.csv`` (one row per update, written as it goes,
so an interrupted run stays readable; with the learning diagnostics of
:data:`tlshield.runs.DIAGNOSTIC_COLUMNS`), ``tb/`` (TensorBoard), ``model.zip`` with
``normalization.json`` (the kept policy: the best on the validation episodes for the default
preset, the last one otherwise), ``last_model.zip`` with ``last_normalization.json`` and, after
evaluation, ``evaluation.json`` and ``trajectories.npz`` (``last_evaluation.json`` for the last
policy). Nothing in a run folder is a pickle that loading would run (:mod:`tlshield.saved`).

PPO presets (:data:`PRESETS`): ``"paper"`` is the paper's networks and batch (separate policy
and value MLPs 300-200-100 with ReLU; 5 environments x 200 steps = 5 trajectories of the horizon
per update; 10 epochs of minibatches of 250; Adam 3e-4; gamma 0.99, clip 0.2); ``"default"`` is
what the ablation in the README and the learning experiments (docs/learning.md) chose (8
environments x 128 steps, minibatches of 512, gamma 0.999, clip 0.1, a learning rate of 1e-3
decaying linearly, 64-64 networks, a Gaussian policy with a tanh-bounded mean, raw rewards, the
best validated checkpoint kept and the last one beside it). Both: GAE lambda 0.95, CPU, one
torch thread (deterministic for a seed).
Observations are normalised by running statistics (SB3 ``VecNormalize``, saved as
``normalization.json`` and used by the evaluation); rewards are normalised too unless the preset
says ``norm_reward: False``; the metrics are in raw units. The policy is one of
:data:`tlshield.policies.POLICIES` (the preset's ``policy``; PPO setting ``policy``).

Reset seeds (:mod:`tlshield.seeds`): training environments from the run seed (``seed * 1000 +
env index``), validation episodes from ``VALIDATION_SEED`` (20,000+), evaluation trials from
``EVAL_SEED`` (10,000+), so the three never meet.
"""

from __future__ import annotations

import csv
import json
import math
import time
from collections.abc import Callable
from dataclasses import asdict, replace
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from tlshield.codes import Status
from tlshield.envs import ENV_ID, check_env_id, check_task_env, make
from tlshield.envs.channel import CONFIGS, ChannelConfig, channel_shield
from tlshield.evaluation import evaluate, rollouts
from tlshield.runs import METRIC_COLUMNS, is_finished, load_run
from tlshield.seeds import check_seeds, train_seed, validation_seed

#: PPO settings by preset: environments, SB3 PPO keywords and the networks.
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
        # The progress reward is bounded by design (bands of width 1 per FSA state, a bonus of
        # about 5), so it needs no running normalisation; with it, a run whose returns stopped
        # varying divided by a tiny std, the value loss reached 1e3-1e4, and the global
        # gradient clip then starved the policy (approx_kl 1e-9): a permanent collapse.
        "norm_reward": False,
        # The learning rate decays linearly to 0 (without it the policy found the task and then
        # lost it again within the same run, measured).
        "lr_schedule": "linear",
        # Every 10 updates the deterministic policy runs 20 validation episodes (reset seeds
        # from VALIDATION_SEED, never used for evaluation); the best checkpoint is kept (the
        # policy found the task and lost it again in some runs, measured).
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
}
#: The CLF-bound schedules of :func:`clf_scale` (the CLI and the tuner offer these).
SCHEDULES = ("fixed", "linear", "exponential")
#: Environments :func:`train` and :func:`tlshield.evaluation.evaluate` know.


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


def _check_run_args(
    config: str, updates: int, schedule: str, final_scale: float, preset: str = "default"
) -> None:
    if preset not in PRESETS:
        raise ValueError(f"preset {preset!r}: expected one of {', '.join(PRESETS)}")
    if config not in CONFIGS:
        raise ValueError(f"config {config!r}: expected one of {', '.join(CONFIGS)}")
    if not (isinstance(updates, int) and updates > 0):
        raise ValueError(f"updates = {updates!r}: expected a positive integer")
    if schedule not in SCHEDULES:
        raise ValueError(f"clf schedule {schedule!r}: expected one of {', '.join(SCHEDULES)}")
    if not (0.0 < final_scale <= 1.0):
        raise ValueError(f"final CLF scale {final_scale!r}: expected a number in (0, 1]")


def _env_config(venv: Any) -> Any:
    """The first sub-environment's config dataclass, or None (a user's environment)."""
    try:
        return venv.env_method("get_wrapper_attr", "cfg", indices=[0])[0]
    except AttributeError:
        return None


def make_vec_env(
    config: str, seed: int, overrides: dict[str, Any], n_envs: int, env_id: str = ENV_ID
) -> Any:
    """The training VecEnv: ``n_envs`` copies of ``env_id`` (Channel-v0 by default), each
    shielding its own steps (Channel-v0's shield needs each env's measured obstacle motion; at
    3 us a call, batching 8 rows would save nothing), seeded ``seed * 1000 + i``."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    venv = DummyVecEnv([partial(make, env_id, config, **overrides)] * n_envs)
    venv.seed(train_seed(seed))
    return venv


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
        self.relaxed = self.failed = self.steps = 0
        self.correction = 0.0

    def step(self, rewards: np.ndarray, dones: np.ndarray, infos: list[dict[str, Any]]) -> None:
        self.discounted += self.discount * rewards
        self.discount *= self.gamma
        for i, info in enumerate(infos):
            h = info.get("constraints", {})  # Channel-v0's c1, c2 (other envs: not recorded)
            self.min_h[0] = min(self.min_h[0], h.get("c1", math.inf))
            self.min_h[1] = min(self.min_h[1], h.get("c2", math.inf))
            self.min_d = min(self.min_d, info.get("min_obstacle_distance", math.inf))
            self.violations += bool(info.get("violation", False))
            self.trap_entries += info["trap"] and not self.was_trapped[i]
            self.was_trapped[i] = info["trap"]
            self.successes += info["success"]
            shield = info.get("shield", {})
            status = shield.get("status")
            self.relaxed += status in (Status.RELAXED, Status.INACCURATE)
            self.failed += status == Status.FAILED
            self.steps += 1
            if "a_cbf" in shield:  # |a_applied - a_rl|: what the shield and the CLF overruled
                self.correction += float(np.linalg.norm(shield["a_cbf"] + shield["a_clf"]))
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
    preset: str = "default",
    ppo: dict[str, Any] | None = None,
    env: str = ENV_ID,
    on_update: Callable[[dict[str, float]], Any] | None = None,
    **overrides: Any,
) -> Path:
    """Trains PPO on one configuration of ``env`` (Channel-v0 by default, or
    ``"tlshield/PointMass-v0"``); returns the run folder. ``overrides`` are the environment's
    config fields (``ChannelConfig``, ``PointMassConfig``). Ctrl-C stops cleanly: the metrics
    so far and the model are kept (``config.json`` then says ``"interrupted": true``).
    ``on_update`` is called with each update's metrics row (:data:`tlshield.runs.METRIC_COLUMNS`)
    once it is written."""
    _check_run_args(config, updates, clf_schedule, clf_final_scale, preset)
    check_seeds((seed,))
    check_env_id(env)
    if env != ENV_ID and clf_schedule != "fixed":
        raise ValueError(f"clf schedule {clf_schedule!r}: only 'fixed' outside {ENV_ID}")
    spec = PRESETS[preset]
    ppo_kwargs, n_envs, net_arch = {**spec["ppo"], **(ppo or {})}, spec["n_envs"], spec["net_arch"]
    log_std_init = float(ppo_kwargs.pop("log_std_init", spec.get("log_std_init", 0.0)))
    n_envs = int(ppo_kwargs.pop("n_envs", n_envs))
    policy_name = str(ppo_kwargs.pop("policy", spec.get("policy", "gaussian")))
    norm_reward = bool(ppo_kwargs.pop("norm_reward", spec.get("norm_reward", True)))
    from tlshield.policies import policy_class

    policy_class(policy_name)  # an unknown name fails here, before any environment is built
    # The progress reward is shaped for the discount PPO uses (the bundled environments take
    # it as a keyword; a user's environment is checked below).
    if env.startswith("tlshield/"):
        overrides = {"gamma": ppo_kwargs["gamma"], **overrides}
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.logger import configure

    torch.set_num_threads(1)
    run = Path(out)
    run.mkdir(parents=True, exist_ok=True)
    from stable_baselines3.common.vec_env import VecNormalize

    check_task_env(make(env, config, **overrides), ppo_kwargs["gamma"], env)
    inner = make_vec_env(config, seed, overrides, n_envs, env)
    cfg: Any = _env_config(inner)
    venv = VecNormalize(inner, norm_obs=True, norm_reward=norm_reward, gamma=ppo_kwargs["gamma"])
    record = {
        "env_id": env,
        "config": config,
        "seed": seed,
        "updates": updates,
        "preset": preset,
        "clf_schedule": clf_schedule,
        "clf_final_scale": clf_final_scale,
        "n_envs": n_envs,
        "ppo": {
            **ppo_kwargs,
            "lr_schedule": spec.get("lr_schedule", "constant"),
            "log_std_init": log_std_init,
            "policy": policy_name,
            "norm_reward": norm_reward,
            "net_arch": net_arch,
            "activation": "ReLU",
        },
        "env": asdict(cfg) if cfg is not None else {},
        "overrides": overrides,
        "interrupted": False,
        "finished": False,
    }
    (run / "config.json").write_text(json.dumps(record, indent=2))

    learning_rate: Any = ppo_kwargs["learning_rate"]
    if spec.get("lr_schedule") == "linear":
        start_lr = float(learning_rate)
        learning_rate = lambda remaining: start_lr * remaining  # noqa: E731
    from tlshield.saved import save_normalization

    model = PPO(
        policy_class(policy_name),
        venv,
        seed=seed,
        device="cpu",
        verbose=0,
        policy_kwargs={
            "net_arch": net_arch,
            "activation_fn": torch.nn.ReLU,
            "log_std_init": log_std_init,
        },
        **{**ppo_kwargs, "learning_rate": learning_rate},
    )
    model.set_logger(configure(str(run / "tb"), ["tensorboard"]))
    metrics = _Metrics(n_envs, ppo_kwargs["gamma"])
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
            self.best = -1.0

        def _on_rollout_start(self) -> None:
            self.scale = clf_scale(clf_schedule, self.update / max(updates - 1, 1), clf_final_scale)
            if CONFIGS[config][1] and clf_schedule != "fixed":
                inner.set_attr("shield", channel_shield(_scaled(cfg, self.scale), config))

        def _on_step(self) -> bool:
            raw = venv.get_original_reward()  # metrics in raw units, not normalised
            metrics.step(raw, self.locals["dones"], self.locals["infos"])
            return True

        def _validate(self) -> float:
            """Every ``validate_every`` updates: validation success of the deterministic
            policy; the best so far (ties: the later) is saved as the run's model."""
            every = spec.get("validate_every")
            if not every or self.update % every:
                return math.nan
            trials = int(spec["validation_trials"])
            seeds = [validation_seed(seed, i) for i in range(trials)]

            def policy(obs: np.ndarray) -> np.ndarray:
                return model.predict(venv.normalize_obs(obs), deterministic=True)[0]

            outcomes = rollouts(config, overrides, policy, seeds, env)[0]
            success = sum(o["success"] for o in outcomes) / trials
            if success >= self.best:
                self.best = success
                model.save(run / "model.zip")
                save_normalization(venv, run / "normalization.json")
                record["kept"] = {"update": self.update, "validation_success": success}
            return success

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
                "validation_success": self._validate(),
                "wall_time": time.perf_counter() - start,
                **_diagnostics(self.model, metrics),
            }
            writer.writerow(row)
            csv_file.flush()
            if on_update is not None:
                on_update(row)
            for key, value in row.items():
                if key not in ("update", "timesteps"):
                    self.logger.record(f"tlshield/{key}", value)
            metrics.reset_update()
            bar.update(1)
            bar.set_postfix(ret=f"{row['return_mean']:.1f}", viol=row["violations"])

    try:
        model.learn(total_timesteps=updates * n_envs * ppo_kwargs["n_steps"], callback=Callback())
        record["finished"] = True
    except KeyboardInterrupt:
        record["interrupted"] = True
    finally:
        bar.close()
        csv_file.close()
        # The last policy is kept beside the validated one (model.zip, what evaluate reads);
        # without validation they are the same.
        model.save(run / "last_model.zip")
        save_normalization(venv, run / "last_normalization.json")
        if "kept" not in record:
            model.save(run / "model.zip")
            save_normalization(venv, run / "normalization.json")
        record["wall_time"] = time.perf_counter() - start
        (run / "config.json").write_text(json.dumps(record, indent=2))
        venv.close()
    if record["interrupted"]:
        raise KeyboardInterrupt
    return run


def _diagnostics(model: Any, metrics: _Metrics) -> dict[str, float]:
    """The learning diagnostics of one update (:data:`tlshield.runs.DIAGNOSTIC_COLUMNS`): the
    policy's std per dimension, the sampled actions outside the box, the shield's mean
    correction and relaxed rate, and the statistics of PPO's last gradient step (logged by SB3
    before this rollout; NaN before the first)."""
    import torch

    log_std = getattr(model.policy, "log_std", None)
    std = torch.exp(log_std).detach().cpu().numpy() if log_std is not None else np.array([])
    actions = np.asarray(model.rollout_buffer.actions).reshape(-1, model.action_space.shape[0])
    low, high = model.action_space.low, model.action_space.high
    logged = model.logger.name_to_value
    steps = max(metrics.steps, 1)
    return {
        "policy_std_0": float(std[0]) if len(std) > 0 else math.nan,
        "policy_std_1": float(std[1]) if len(std) > 1 else math.nan,
        "out_of_box": float(np.mean(np.any((actions < low) | (actions > high), axis=1))),
        "mean_correction": metrics.correction / steps,
        "relaxed_rate": metrics.relaxed / steps,
        **{
            name: float(logged.get(f"train/{name}", math.nan))
            for name in (
                "approx_kl",
                "clip_fraction",
                "explained_variance",
                "value_loss",
                "entropy_loss",
            )
        },
    }


def _progress_bar(total: int, desc: str, enabled: bool, unit: str = "update") -> Any:
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit=unit, disable=not enabled, leave=False)


def run_job(
    config: str, seed: int, updates: int, trials: int, options: dict[str, Any], folder: Path
) -> Path:
    """One (config, seed) of a sweep: train into ``folder``, then evaluate the kept and the
    last policy (a Ray task)."""
    import torch

    torch.set_num_threads(1)
    train(config, seed, updates, folder, progress=False, **options)
    evaluate(folder, trials=trials)
    evaluate(folder, trials=trials, which="last")
    return folder


def reproduce(
    out: str | Path,
    *,
    configs: tuple[str, ...] = tuple(CONFIGS),
    seeds: tuple[int, ...] = (0, 1),
    updates: int = 300,
    trials: int = 100,
    workers: int | None = None,
    address: str | None = None,
    progress: bool = True,
    **options: Any,
) -> Path:
    """Trains and evaluates every configuration x seed as Ray tasks (a local Ray with
    ``workers`` CPUs, all cores by default, or the cluster at ``address``; see
    :mod:`tlshield.cluster`), then writes the figures (``out/figures``) and the results table
    (``out/results.md``). Runs that already finished and were evaluated (same folder) are
    kept, so an interrupted reproduction resumes."""
    for config in configs:
        _check_run_args(
            config,
            updates,
            options.get("clf_schedule", "fixed"),
            options.get("clf_final_scale", 0.2),
            options.get("preset", "default"),
        )
    check_seeds(seeds)
    if not (isinstance(trials, int) and trials > 0):
        raise ValueError(f"trials = {trials!r}: expected a positive integer")
    root = Path(out)
    root.mkdir(parents=True, exist_ok=True)
    jobs = {}
    for config in configs:
        for seed in seeds:
            folder = root / f"{config}_s{seed}"
            if not ((folder / "evaluation.json").is_file() and is_finished(folder, updates)):
                jobs[folder] = partial(run_job, config, seed, updates, trials, options)
    _run_jobs(jobs, workers, address, progress)
    from tlshield.plots import plot_all
    from tlshield.report import results_table, seeds_table

    plot_all(root)
    (root / "results.md").write_text(f"{results_table(root)}\n\n{seeds_table(root)}\n")
    return root


def _run_jobs(
    jobs: dict[Path, Any], workers: int | None, address: str | None, progress: bool
) -> None:
    """Runs the jobs as Ray tasks, gathering each run folder as it finishes."""
    if not jobs:
        return
    from tlshield import cluster

    bar = _progress_bar(len(jobs), "runs", progress, unit="run")
    try:
        with cluster.session(address, workers):
            cluster.run(jobs, on_done=lambda _: bar.update(1))
    finally:
        bar.close()


def _ablation_rows() -> list[tuple[str, dict[str, Any]]]:
    """From the paper's settings, one change at a time, to tlshield's defaults."""
    from tlshield.envs.channel import PAPER_ENV

    paper = {"preset": "paper", **PAPER_ENV}
    reward = {**paper, "reward": "progress", "w": 0.05, "collision_penalty": 1.0}
    observation = {**reward, "observation": "relative"}
    barrier = {**observation, "obstacle_barrier": True}
    intervention = {**barrier, "intervention_penalty": 0.05}
    return [
        ("paper settings (Eq. 5A1, 13-value obs., paper PPO)", paper),
        ("+ progress reward", reward),
        ("+ relative body-frame observation", observation),
        ("+ moving-obstacle barrier", barrier),
        ("+ intervention penalty", intervention),
        (
            "default PPO preset, no intervention penalty (= tlshield's defaults)",
            {"preset": "default"},
        ),
    ]


def ablation(
    out: str | Path,
    *,
    config: str = "rl_cbf_clf",
    seeds: tuple[int, ...] = (0, 1),
    updates: int = 300,
    trials: int = 100,
    workers: int | None = None,
    address: str | None = None,
    progress: bool = True,
) -> Path:
    """The README's ablation: each row adds one change to the one before (see
    :func:`_ablation_rows`), trained and evaluated on every seed; writes ``out/ablation.md``.
    Finished rows are kept, so an interrupted ablation resumes."""
    _check_run_args(config, updates, "fixed", 0.2)
    check_seeds(seeds)
    root = Path(out)
    root.mkdir(parents=True, exist_ok=True)
    rows = _ablation_rows()
    jobs = {}
    for k, (_, options) in enumerate(rows):
        for seed in seeds:
            folder = root / f"row{k}_s{seed}"
            if not ((folder / "evaluation.json").is_file() and is_finished(folder, updates)):
                jobs[folder] = partial(run_job, config, seed, updates, trials, options)
    _run_jobs(jobs, workers, address, progress)
    lines = [
        f"| change ({config}, {len(seeds)} seeds x {trials} trials) | eval success per seed "
        "| mean | eval collisions | train violations | train min obstacle distance | relaxed |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for k, (label, _) in enumerate(rows):
        runs = [r for s in seeds if (r := load_run(root / f"row{k}_s{s}")) and r.evaluation]
        if len(runs) != len(seeds):
            raise RuntimeError(f"{root}: row {k} has a run without evaluation.json")
        evals = [r.evaluation or {} for r in runs]
        rates = [e["success_rate"] for e in evals]
        collisions = sum(e["collisions"] for e in evals)
        metrics = [r.metrics for r in runs]
        lines.append(
            f"| {label} | {' / '.join(f'{r:.2f}' for r in rates)} | {np.mean(rates):.2f} "
            f"| {collisions} "
            f"| {int(sum(m['violations'].sum() for m in metrics))} "
            f"| {min(float(np.nanmin(m['min_obstacle_distance'])) for m in metrics):.2f} "
            f"| {int(sum(m['relaxed'].sum() for m in metrics))} |"
        )
    (root / "ablation.md").write_text("\n".join(lines) + "\n")
    return root
