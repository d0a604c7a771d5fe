"""PPO on tlshield/Channel-v0 (Stable-Baselines3) with per-update metrics; the reproduction
and the ablation of docs/reproduction.md (training, then :func:`tlshield.lab.evaluation.evaluate`).

A run folder (schema and loaders: :mod:`tlshield.lab.runs`) holds ``run.json`` (what it ran
with, and which checkpoint was kept), ``metrics.csv`` (one row per update, written as it goes,
so an interrupted run stays readable; with the learning diagnostics of
:data:`tlshield.lab.runs.DIAGNOSTIC_COLUMNS`), ``tb/`` (TensorBoard), ``model.zip`` with
``normalization.json`` (the kept policy: the best on the validation episodes for the default
preset, the last one otherwise), ``last_model.zip`` with ``last_normalization.json`` and, after
evaluation, ``evaluation.json`` and ``trajectories.npz`` (``last_evaluation.json`` for the last
policy). Nothing in a run folder is a pickle that loading would run (:mod:`tlshield.lab.saved`).

PPO presets (:data:`PRESETS`): ``"paper"`` is the paper's networks and batch (separate policy
and value MLPs 300-200-100 with ReLU; 5 environments x 200 steps = 5 trajectories of the horizon
per update; 10 epochs of minibatches of 250; Adam 3e-4; gamma 0.99, clip 0.2); ``"default"`` is
what the ablation (docs/reproduction.md) and the learning experiments (docs/learning.md) chose (8
environments x 128 steps, minibatches of 512, gamma 0.999, clip 0.1, a learning rate of 1e-3
decaying linearly, 64-64 networks, a Gaussian policy with a tanh-bounded mean, raw rewards,
the best validated checkpoint kept and the last one beside it). Both: GAE lambda 0.95, CPU, one
torch thread (deterministic for a seed).
Observations are normalised by running statistics (SB3 ``VecNormalize``, saved as
``normalization.json`` and used by the evaluation); rewards are normalised too unless the preset
says ``norm_reward: False``; the metrics are in raw units. The policy is one of
:data:`tlshield.lab.policies.POLICIES` (the preset's ``policy``; PPO setting ``policy``).

Seeds (:mod:`tlshield.lab.seeds`, any non-negative integer): training environments reset from
``train_seed(seed) + env index``, validation episodes from ``validation_seed(seed, k)`` and
evaluation trials from ``EVAL_SEED + k``, in disjoint ranges, so the three never meet; PPO takes
``learner_seed(seed)``.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from tlshield._removed import refuse
from tlshield.envs import ENV_ID
from tlshield.envs.params import CONFIGS, FULL, as_flat, check_config, flat_names
from tlshield.envs.profile import EnvProfile, load_attr, profile_of
from tlshield.lab.envs import (
    check_env_id,
    check_task_env,
    factory_takes,
    import_modules,
    make,
)
from tlshield.lab.evaluation import evaluate
from tlshield.lab.presets import (
    DEFAULT_FINAL_SCALE,
    DEFAULT_SCHEDULE,
    DEFAULT_TRIALS,
    DEFAULT_UPDATES,
    PRESETS,
    SCHEDULES,
    STUDY_UPDATES,
)
from tlshield.lab.runs import RUN_FILE, is_finished, load_run
from tlshield.lab.seeds import check_seeds, learner_seed, train_seed


def _check_run_args(
    config: str, updates: int, schedule: str, final_scale: float, preset: str = "default"
) -> None:
    if preset not in PRESETS:
        raise ValueError(f"preset {preset!r}: expected one of {', '.join(PRESETS)}")
    check_config(config)
    if not (isinstance(updates, int) and updates > 0):
        raise ValueError(f"updates = {updates!r}: expected a positive integer")
    if schedule not in SCHEDULES:
        raise ValueError(f"clf schedule {schedule!r}: expected one of {', '.join(SCHEDULES)}")
    if not (0.0 < final_scale <= 1.0):
        raise ValueError(f"final CLF scale {final_scale!r}: expected a number in (0, 1]")


def _env_params(venv: Any) -> Any:
    """The first sub-environment's parameters (``params``), or None (a user's environment)."""
    try:
        return venv.env_method("get_wrapper_attr", "params", indices=[0])[0]
    except AttributeError:
        return None


def train(config: str, seed: int, updates: int, out: str | Path, **options: Any) -> Path:
    """Trains PPO on one configuration of an environment (Channel-v0 by default); returns the
    run folder. ``learn(prepare(config, seed, updates, out, **options))``: the options and the
    environment's parameters are the keywords of :func:`prepare`."""
    return learn(prepare(config, seed, updates, out, **options))


def prepare(
    config: str,
    seed: int,
    updates: int,
    out: str | Path,
    *,
    clf_schedule: str = DEFAULT_SCHEDULE,
    clf_final_scale: float = DEFAULT_FINAL_SCALE,
    progress: bool = True,
    preset: str = "default",
    ppo: dict[str, Any] | None = None,
    env: str = ENV_ID,
    on_update: Callable[[dict[str, float]], Any] | None = None,
    imports: Sequence[str] = (),
    **overrides: Any,
) -> Any:
    """The first half of :func:`train`: checks the arguments, builds the environments and the
    model and writes ``run.json``; returns the :class:`tlshield.lab.callbacks.TrainingRun` that
    :func:`learn` trains (its ``model`` stays usable afterwards, as the benchmarks use it).

    ``env`` is Channel-v0 by default, or ``"tlshield/PointMass-v0"``, FlatWorld-v0 or a user's
    registered environment; ``overrides`` are the environment's parameters by flat name
    (``ChannelParams``, ``PointMassParams``). Ctrl-C stops :func:`learn` cleanly: the metrics
    so far and the model are kept (``run.json`` then says ``"interrupted": true``).
    ``on_update`` is called with each update's metrics row
    (:data:`tlshield.lab.runs.METRIC_COLUMNS`) once it is written. ``env`` may be
    ``"module:Env-v0"`` (``module`` is imported first, as ``gymnasium.make`` does);
    ``imports`` are modules to import before it (where a user's environments register
    themselves). Both are recorded in ``run.json``, so that
    :func:`tlshield.lab.evaluation.evaluate` finds the environment again."""
    _check_run_args(config, updates, clf_schedule, clf_final_scale, preset)
    check_seeds((seed,))
    imports = list(imports)
    import_modules(imports)
    check_env_id(env)
    profile = profile_of(env)
    if profile.clf_shield is None and clf_schedule != DEFAULT_SCHEDULE:
        raise ValueError(
            f"clf schedule {clf_schedule!r}: env {env!r} has none (its profile names no "
            "clf_shield to rebuild its shield with); use 'fixed'"
        )
    settings = _ppo_settings(preset, ppo)
    # The progress reward is shaped for the discount PPO uses (the bundled environments take
    # it as a keyword; a user's environment is checked below).
    if _takes_gamma(env, profile):
        overrides = {"gamma": settings.ppo["gamma"], **overrides}
    import torch
    from stable_baselines3.common.vec_env import VecNormalize

    from tlshield.lab.callbacks import TrainingRun
    from tlshield.sb3 import make_vec_env

    torch.set_num_threads(1)
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    check_task_env(make(env, config, **overrides), settings.ppo["gamma"], env)
    inner = make_vec_env(env, settings.n_envs, config, seed=train_seed(seed), **overrides)
    venv = VecNormalize(
        inner,
        norm_obs=settings.norm_obs,
        norm_reward=settings.norm_reward,
        gamma=settings.ppo["gamma"],
    )
    params = _env_params(inner)
    schedule = (clf_schedule, clf_final_scale)
    record = _run_record(env, config, seed, updates, preset, schedule, settings, params, overrides)
    record["imports"] = imports
    (folder / RUN_FILE).write_text(json.dumps(record, indent=2))
    return TrainingRun(
        folder=folder,
        record=record,
        model=_ppo(settings, venv, seed),
        venv=venv,
        inner=inner,
        env_id=env,
        config=config,
        params=params,
        seed=seed,
        updates=updates,
        overrides=overrides,
        clf_schedule=clf_schedule,
        clf_final_scale=clf_final_scale,
        rescale_clf=_clf_rescaler(profile, config, clf_schedule, inner, params),
        validate_every=PRESETS[preset].get("validate_every"),
        validation_trials=int(PRESETS[preset].get("validation_trials", 0)),
        on_update=on_update,
        progress=progress,
    )


def _takes_gamma(env: str, profile: EnvProfile) -> bool:
    """Whether the env's reward is sized by a discount it takes as ``gamma``: a parameter of
    its profile's parameters class, or else a keyword its factory names (an env scored by
    return has its own reward)."""
    if profile.scored_by_return:
        return False
    cls = profile.params_class()
    return "gamma" in flat_names(cls) if cls is not None else factory_takes(env, "gamma")


def scaled_clf(params: Any, scale: float) -> Any:
    """``params`` with its CLF box (``shield.clf_bounds``) scaled by ``scale``."""
    lo, hi = params.shield.clf_bounds
    return params.replace(clf_bounds=(tuple(x * scale for x in lo), tuple(x * scale for x in hi)))


def _clf_rescaler(
    profile: EnvProfile, config: str, clf_schedule: str, inner: Any, params: Any
) -> Callable[[float], None] | None:
    """What :class:`tlshield.lab.callbacks.ClfSchedule` calls with each rollout's scale: the
    env's shield rebuilt with the CLF box scaled (by the ``clf_shield`` its profile names),
    set on every training environment; None when there is nothing to scale."""
    if profile.clf_shield is None or clf_schedule == DEFAULT_SCHEDULE or not CONFIGS[config][1]:
        return None
    shield_of = load_attr(profile.clf_shield)

    def rescale(scale: float) -> None:
        inner.set_attr("shield", shield_of(scaled_clf(params, scale), config))

    return rescale


#: What PPO's rollout stores as the action taken (setting ``learn_from``): the sampled action
#: (SB3's own), the executed one, or the executed one without the CLF's part
#: (:class:`tlshield.lab.callbacks.ExecutedActions`).
LEARN_FROM = ("sampled", "executed", "executed_without_clf")
#: How PPO's learning rate moves over a run (setting ``lr_schedule``), and its entropy
#: coefficient (``ent_schedule``, from ``ent_coef``): held, or decayed linearly to 0.
LR_SCHEDULES = ("constant", "linear")


@dataclass(frozen=True)
class PpoSettings:
    """What one run's PPO is made of: SB3 keywords, environments, networks and the policy."""

    ppo: dict[str, Any]
    n_envs: int
    net_arch: dict[str, list[int]]
    log_std_init: float
    policy: str
    activation: str
    norm_obs: bool
    norm_reward: bool
    lr_schedule: str
    learn_from: str
    ent_schedule: str = "constant"


def _ppo_settings(preset: str, ppo: dict[str, Any] | None) -> PpoSettings:
    """The preset's PPO settings with ``ppo``'s on top; the tlshield-only keys (``n_envs``,
    ``policy``, ``norm_reward``, ``log_std_init``, ``learn_from``, ``lr_schedule``,
    ``ent_schedule``) are taken
    out of SB3's keywords."""
    from tlshield.lab.policies import policy_class
    from tlshield.lab.saved import activation_class

    spec = PRESETS[preset]
    kwargs = {**spec["ppo"], **(ppo or {})}
    settings = PpoSettings(
        log_std_init=float(kwargs.pop("log_std_init", spec.get("log_std_init", 0.0))),
        n_envs=int(kwargs.pop("n_envs", spec["n_envs"])),
        policy=str(kwargs.pop("policy", spec.get("policy", "gaussian"))),
        activation=str(spec.get("activation", "ReLU")),
        norm_obs=bool(spec.get("norm_obs", True)),
        norm_reward=bool(kwargs.pop("norm_reward", spec.get("norm_reward", True))),
        learn_from=str(kwargs.pop("learn_from", spec.get("learn_from", "sampled"))),
        ppo=kwargs,
        net_arch=spec["net_arch"],
        lr_schedule=str(kwargs.pop("lr_schedule", spec.get("lr_schedule", "constant"))),
        ent_schedule=str(kwargs.pop("ent_schedule", spec.get("ent_schedule", "constant"))),
    )
    policy_class(settings.policy)  # an unknown name fails here, before any environment is built
    activation_class(settings.activation)
    if settings.learn_from not in LEARN_FROM:
        raise ValueError(f"learn_from = {settings.learn_from!r}: expected one of {LEARN_FROM}")
    for key in ("lr_schedule", "ent_schedule"):
        if getattr(settings, key) not in LR_SCHEDULES:
            raise ValueError(f"{key} = {getattr(settings, key)!r}: expected one of {LR_SCHEDULES}")
    if settings.ppo.get("use_sde") and settings.policy != "gaussian":
        # SB3's gSDE replaces the policy's Gaussian head: only its own policy has one.
        raise ValueError(f"use_sde needs policy 'gaussian', not {settings.policy!r}")
    return settings


def _run_record(
    env: str,
    config: str,
    seed: int,
    updates: int,
    preset: str,
    schedule: tuple[str, float],
    settings: PpoSettings,
    params: Any,
    overrides: dict[str, Any],
) -> dict[str, Any]:
    """The run's ``run.json``: what it ran with (:mod:`tlshield.lab.runs` reads it back)."""
    return {
        "env_id": env,
        "config": config,
        "seed": seed,
        "updates": updates,
        "preset": preset,
        "clf_schedule": schedule[0],
        "clf_final_scale": schedule[1],
        "n_envs": settings.n_envs,
        "ppo": {
            **settings.ppo,
            "lr_schedule": settings.lr_schedule,
            "ent_schedule": settings.ent_schedule,
            "log_std_init": settings.log_std_init,
            "policy": settings.policy,
            "norm_reward": settings.norm_reward,
            "learn_from": settings.learn_from,
            "net_arch": settings.net_arch,
            "activation": settings.activation,
            "norm_obs": settings.norm_obs,
        },
        "env": as_flat(params),
        "overrides": overrides,
        "interrupted": False,
        "finished": False,
    }


def _ppo(settings: PpoSettings, venv: Any, seed: int) -> Any:
    """The SB3 PPO model of ``settings`` on ``venv`` (CPU, seeded)."""
    from stable_baselines3 import PPO

    from tlshield.lab.policies import policy_class
    from tlshield.lab.saved import activation_class

    learning_rate: Any = settings.ppo["learning_rate"]
    if settings.lr_schedule == "linear":
        start_lr = float(learning_rate)
        learning_rate = lambda remaining: start_lr * remaining  # noqa: E731
    return PPO(
        policy_class(settings.policy),
        venv,
        seed=learner_seed(seed),
        device="cpu",
        verbose=0,
        policy_kwargs={
            "net_arch": settings.net_arch,
            "activation_fn": activation_class(settings.activation),
            "log_std_init": settings.log_std_init,
        },
        **{**settings.ppo, "learning_rate": learning_rate},
    )


def learn(run: Any) -> Path:
    """The second half of :func:`train`: trains ``run`` (from :func:`prepare`) for its updates
    with its callbacks, then keeps the last policy (and the kept one when validation chose
    none) and the final ``run.json``, also when interrupted (Ctrl-C is raised again
    afterwards). Returns the run folder."""
    from tlshield.lab.callbacks import EntropySchedule, ExecutedActions, TrainingCallback
    from tlshield.lab.saved import save_normalization

    model, venv, record, folder = run.model, run.venv, run.record, run.folder
    before: list[Any] = []
    learn_from = record["ppo"]["learn_from"]
    if learn_from != "sampled":
        # First: the rollout holds the executed actions before anything else reads the step.
        before.append(ExecutedActions(run.inner, learn_from == "executed_without_clf"))
    if record["ppo"].get("ent_schedule", "constant") == "linear":
        before.append(EntropySchedule(float(record["ppo"]["ent_coef"]), run.updates))
    callback = TrainingCallback(run)
    timesteps = run.updates * run.inner.num_envs * model.n_steps
    try:
        model.learn(total_timesteps=timesteps, callback=[*before, callback])
        record["finished"] = True
    except KeyboardInterrupt:
        record["interrupted"] = True
    finally:
        callback.close()
        # The last policy is kept beside the validated one (model.zip, what evaluate reads);
        # without validation they are the same.
        model.save(folder / "last_model.zip")
        save_normalization(venv, folder / "last_normalization.json")
        if "kept" not in record:
            model.save(folder / "model.zip")
            save_normalization(venv, folder / "normalization.json")
        record["wall_time"] = callback.elapsed()
        # Per barrier, the training steps on which it gave way.
        record["gave_way"] = dict(sorted(callback.gave_way().items()))
        (folder / RUN_FILE).write_text(json.dumps(record, indent=2))
        venv.close()
    if record["interrupted"]:
        raise KeyboardInterrupt
    return Path(folder)


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


def sweep(
    root: Path,
    runs: Sequence[tuple[str, str, dict[str, Any]]],
    seeds: Sequence[int],
    updates: int,
    trials: int,
    workers: int | None = None,
    address: str | None = None,
    progress: bool = True,
) -> None:
    """Trains and evaluates each run ``(name, config, options)`` on every seed, into
    ``root/{name}_s{seed}``, as Ray tasks (:func:`tlshield.lab.cluster.run_counted`). Runs that
    already finished and were evaluated are kept, so an interrupted sweep resumes. Every
    argument is checked before any job starts."""
    for _, config, options in runs:
        _check_run_args(
            config,
            updates,
            options.get("clf_schedule", DEFAULT_SCHEDULE),
            options.get("clf_final_scale", DEFAULT_FINAL_SCALE),
            options.get("preset", "default"),
        )
    check_seeds(seeds)
    if not (isinstance(trials, int) and trials > 0):
        raise ValueError(f"trials = {trials!r}: expected a positive integer")
    root.mkdir(parents=True, exist_ok=True)
    jobs = {}
    for name, config, options in runs:
        for seed in seeds:
            folder = root / f"{name}_s{seed}"
            if not ((folder / "evaluation.json").is_file() and is_finished(folder, updates)):
                jobs[folder] = partial(run_job, config, seed, updates, trials, options)
    from tlshield.lab import cluster

    cluster.run_counted(jobs, address, workers, progress)


def reproduce(
    out: str | Path,
    *,
    configs: tuple[str, ...] = tuple(CONFIGS),
    seeds: tuple[int, ...] = (0, 1),
    updates: int = DEFAULT_UPDATES,
    trials: int = DEFAULT_TRIALS,
    workers: int | None = None,
    address: str | None = None,
    progress: bool = True,
    **options: Any,
) -> Path:
    """Trains and evaluates every configuration x seed (:func:`sweep`: a local Ray with
    ``workers`` CPUs, all cores by default, or the cluster at ``address``; see
    :mod:`tlshield.lab.cluster`), then writes the figures (``out/figures``) and the results table
    (``out/results.md``). Runs that already finished and were evaluated (same folder) are
    kept, so an interrupted reproduction resumes."""
    root = Path(out)
    runs = [(config, config, options) for config in configs]
    sweep(root, runs, seeds, updates, trials, workers, address, progress)
    from tlshield.lab.plots import plot_all
    from tlshield.lab.report import results_table, seeds_table

    plot_all(root)
    (root / "results.md").write_text(f"{results_table(root)}\n\n{seeds_table(root)}\n")
    return root


def _ablation_rows() -> list[tuple[str, dict[str, Any]]]:
    """From the paper's settings, one change at a time, to tlshield's defaults."""
    from tlshield.envs.channel import PAPER_ENV

    paper = {"preset": "paper", **PAPER_ENV}
    reward = {**paper, "reward": "progress", "w": 0.05, "collision_penalty": 1.0}
    observation = {**reward, "observation": "relative"}
    barrier = {**observation, "obstacle_barrier": True}
    intervention = {**barrier, "intervention_penalty": 0.05}
    goal = {**intervention, "goal_weight": 0.5, "end_on_trap": True}
    return [
        ("paper settings (Eq. 5A1, 13-value obs., paper PPO)", paper),
        ("+ progress reward", reward),
        ("+ relative body-frame observation", observation),
        ("+ moving-obstacle barrier", barrier),
        ("+ intervention penalty", intervention),
        ("+ the goal term, training episodes ending in the trap", goal),
        (
            "default PPO preset, no intervention penalty (= tlshield's defaults)",
            {"preset": "default"},
        ),
    ]


def ablation(
    out: str | Path,
    *,
    config: str = FULL,
    seeds: tuple[int, ...] = (0, 1),
    updates: int = STUDY_UPDATES,
    trials: int = DEFAULT_TRIALS,
    workers: int | None = None,
    address: str | None = None,
    progress: bool = True,
) -> Path:
    """The ablation of docs/reproduction.md: each row adds one change to the one before (see
    :func:`_ablation_rows`), trained and evaluated on every seed; writes ``out/ablation.md``.
    Finished rows are kept, so an interrupted ablation resumes."""
    root = Path(out)
    rows = _ablation_rows()
    named = [(f"row{k}", config, options) for k, (_, options) in enumerate(rows)]
    sweep(root, named, seeds, updates, trials, workers, address, progress)
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


#: Names removed in 0.4, refused with a message naming what replaced them.
__getattr__ = refuse(
    __name__,
    {
        "make_vec_env": (
            "tlshield.sb3.make_vec_env(env_id, n_envs, config, seed=train_seed(seed), **overrides)"
        )
    },
)
