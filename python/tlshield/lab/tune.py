"""``tlshield tune``: a search over the task, shield and PPO settings with Ray Tune, Optuna's
TPE sampler and ASHA early stopping (the paper's future work: take the tuning off the user).

Each sample trains one run of the configuration (training seed ``seed``) and reports after
every PPO update a ``score``: the best validation success so far (validation reset seeds
:func:`tlshield.lab.seeds.validation_seed`), or -1 once a shielded run violated the channel. ASHA
stops the samples whose score trails at its rungs. A sample that trains to the end is evaluated
on the tuning seeds (:data:`tlshield.lab.seeds.TUNE_SEED` + trial, disjoint from the training,
validation and evaluation seeds, so ``tlshield evaluate`` on the chosen settings measures on
seeds the search never saw); its ``objective`` is the evaluation success rate when no step
violated the channel (in the evaluation, and in training for configurations with a CBF), else
-1: violations are a hard constraint, and only samples that meet it can be chosen.

Writes, in the output folder: ``best.json`` (``{"config", "objective", "settings", ...}``,
usable as ``tlshield train --settings``), ``trials.csv`` and ``trials.md`` (every sample: its
settings, how far it trained, its objective) and ``trials.png`` (objective against each
searched setting). Ray Tune's own records are under ``ray/``.
"""

from __future__ import annotations

import csv
import json
import math
import re
import tempfile
import time
from collections.abc import Sequence
from functools import partial
from pathlib import Path
from typing import Any

from tlshield.envs.channel import CONFIGS, ChannelParams
from tlshield.envs.params import FULL, check_config
from tlshield.lab.presets import DEFAULT_SCHEDULE, PRESETS, SCHEDULES, STUDY_UPDATES
from tlshield.lab.seeds import MAX_TRIALS, TUNE_SEED
from tlshield.lab.settings import split

#: The searchable settings: name -> (the configurations' part it needs: "cbf", "clf" or "",
#: Optuna suggestion: ("float", low, high, log) / ("int", low, high) / ("choice", options)).
#: ``clf_bounds`` and ``cbf_bounds`` are searched as scales of their default boxes; the CBF box
#: is kept at least the RL box plus the CLF box, so that stopping stays feasible.
SPACE: dict[str, tuple[str, tuple[Any, ...]]] = {
    "c_r": ("", ("float", 0.1, 10.0, True)),
    "w": ("", ("float", 0.005, 0.5, True)),
    "alpha": ("cbf", ("float", 0.5, 10.0, True)),
    "cbf_bounds": ("cbf", ("float", 0.75, 2.0, False)),
    "c3": ("clf", ("float", 0.1, 10.0, True)),
    "k": ("clf", ("float", 1e2, 1e6, True)),
    "clf_bounds": ("clf", ("float", 0.25, 2.0, True)),
    "clf_schedule": ("clf", ("choice", SCHEDULES)),
    "clf_final_scale": ("clf", ("float", 0.05, 1.0, False)),
    "learning_rate": ("", ("float", 1e-4, 3e-3, True)),
    "ent_coef": ("", ("float", 1e-6, 1e-2, True)),
    "n_epochs": ("", ("int", 3, 20)),
    "batch_size": ("", ("choice", (128, 256, 512, 1024))),
}


def _floor(name: str, value: float) -> float:
    """``value`` raised to the lowest value the search range of ``name`` holds (a log range
    cannot hold the preset's ``ent_coef`` of 0)."""
    return max(value, SPACE[name][1][1])


_CFG = ChannelParams()
_PPO = PRESETS["default"]["ppo"]
#: What each searched setting is when it is not searched, as sampled (the first trial): read
#: from :class:`ChannelParams` and the default preset, never copied.
DEFAULTS: dict[str, Any] = {
    "c_r": _CFG.task.c_r,
    "w": _CFG.obstacles.w,
    "alpha": _CFG.shield.alpha,
    "cbf_bounds": 1.0,
    "c3": _CFG.shield.c3,
    "k": _CFG.shield.k,
    "clf_bounds": 1.0,
    "clf_schedule": SCHEDULES[0],
    "learning_rate": _PPO["learning_rate"],
    "ent_coef": _floor("ent_coef", _PPO["ent_coef"]),
    "n_epochs": _PPO["n_epochs"],
    "batch_size": _PPO["batch_size"],
}


def searchable(config: str) -> tuple[str, ...]:
    """The settings :func:`tune` can search for ``config`` (CBF settings need a CBF, ...)."""
    cbf, clf = CONFIGS[config]
    parts = {"": True, "cbf": cbf, "clf": clf}
    return tuple(name for name, (part, _) in SPACE.items() if parts[part])


def to_settings(params: dict[str, Any], config: str) -> dict[str, Any]:
    """Named settings (:mod:`tlshield.lab.settings`) of one sample's parameters: the bound
    scales become boxes, the rest is as sampled."""
    out = {k: v for k, v in params.items() if k not in ("clf_bounds", "cbf_bounds")}
    if "clf_bounds" in params or "cbf_bounds" in params:
        env_params = ChannelParams()
        cbf, clf = CONFIGS[config]
        clf_hi = [b * params.get("clf_bounds", 1.0) for b in env_params.shield.clf_bounds[1]]
        if clf:
            out["clf_bounds"] = [[-b for b in clf_hi], clf_hi]
        if cbf:
            scale = params.get("cbf_bounds", 1.0)
            cbf_hi = [
                max(b * scale, r + (c if clf else 0.0))
                for b, r, c in zip(
                    env_params.shield.cbf_bounds[1],
                    env_params.agent.rl_bounds[1],
                    clf_hi,
                    strict=True,
                )
            ]
            out["cbf_bounds"] = [[-b for b in cbf_hi], cbf_hi]
    return out


def _check(config: str, names: Sequence[str], samples: int, updates: int, trials: int) -> None:
    check_config(config)
    known = searchable(config)
    unknown = sorted(set(names) - set(known))
    if unknown:
        raise ValueError(
            f"--search: unknown or not searchable for {config}: {', '.join(unknown)}; "
            f"searchable: {', '.join(known)}"
        )
    for name, value in (("samples", samples), ("updates", updates), ("trials", trials)):
        if not (isinstance(value, int) and value > 0):
            raise ValueError(f"{name} = {value!r}: expected a positive integer")
    if trials > MAX_TRIALS:
        raise ValueError(f"trials = {trials}: expected at most {MAX_TRIALS}")


def _define(names: Sequence[str], trial: Any) -> None:
    """Optuna's define-by-run space over ``names`` (``clf_final_scale`` only with a shrinking
    ``clf_schedule``); a module-level function so that Tune can save the searcher."""
    for name in names:
        schedule = trial.params.get("clf_schedule", DEFAULT_SCHEDULE)
        if name == "clf_final_scale" and schedule == DEFAULT_SCHEDULE:
            continue
        kind, *args = SPACE[name][1]
        if kind == "float":
            low, high, log = args
            trial.suggest_float(name, low, high, log=log)
        elif kind == "int":
            trial.suggest_int(name, *args)
        else:
            trial.suggest_categorical(name, list(args[0]))


def _trial(params: dict[str, Any], *, config: str, updates: int, seed: int, trials: int) -> None:
    """One sample (a Ray Tune function trainable): train, report per update, evaluate."""
    import torch
    from ray import tune

    from tlshield.lab.evaluation import evaluate
    from tlshield.lab.training import train

    torch.set_num_threads(1)
    shielded = CONFIGS[config][0]
    state = {"best": 0.0, "violations": 0}

    def on_update(row: dict[str, float]) -> None:
        state["violations"] += int(row["violations"])
        if not math.isnan(row["validation_success"]):
            state["best"] = max(state["best"], row["validation_success"])
        if row["update"] < updates:  # the last report carries the evaluation
            violated = shielded and state["violations"] > 0
            tune.report(
                {
                    "update": int(row["update"]),
                    "score": -1.0 if violated else state["best"],
                    "validation_success": state["best"],
                    "violations": state["violations"],
                }
            )

    kwargs = split(to_settings(params, config))
    with tempfile.TemporaryDirectory(prefix="tlshield-tune-") as tmp:
        run = train(
            config, seed, updates, Path(tmp, "run"), progress=False, on_update=on_update, **kwargs
        )
        result = evaluate(run, trials=trials, seed=TUNE_SEED)
    feasible = result["violation_steps"] == 0 and not (shielded and state["violations"] > 0)
    objective = result["success_rate"] if feasible else -1.0
    tune.report(
        {
            "update": updates,
            "score": objective,
            "objective": objective,
            "feasible": feasible,
            "eval_success": result["success_rate"],
            "eval_violation_steps": result["violation_steps"],
            "eval_collisions": result["collisions"],
            "validation_success": state["best"],
            "violations": state["violations"],
        }
    )


def tune(
    out: str | Path,
    *,
    config: str = FULL,
    samples: int = 32,
    updates: int = STUDY_UPDATES,
    search: Sequence[str] | None = None,
    seed: int = 3,
    trials: int = 50,
    sampler_seed: int = 0,
    workers: int | None = None,
    address: str | None = None,
    progress: bool = True,
) -> Path:
    """Searches ``search`` (default: every setting :func:`searchable` for ``config``) over
    ``samples`` samples of ``updates`` PPO updates each, on a local Ray with ``workers`` CPUs
    or the cluster at ``address``. The first sample is tlshield's defaults. Writes
    ``out/best.json``, ``out/trials.{csv,md,png}``; returns ``out``."""
    from optuna.samplers import TPESampler
    from ray import tune as ray_tune
    from ray.tune.schedulers import ASHAScheduler
    from ray.tune.search.optuna import OptunaSearch

    from tlshield.lab import cluster
    from tlshield.lab.seeds import check_seeds

    names = tuple(search) if search else searchable(config)
    _check(config, names, samples, updates, trials)
    check_seeds((seed,))
    root = Path(out).resolve()
    root.mkdir(parents=True, exist_ok=True)
    defaults = {k: DEFAULTS[k] for k in names if k in DEFAULTS}
    searcher = OptunaSearch(
        space=partial(_define, names),
        metric="score",
        mode="max",
        sampler=TPESampler(seed=sampler_seed),
        points_to_evaluate=[defaults],
    )
    scheduler = ASHAScheduler(
        time_attr="update",
        metric="score",
        mode="max",
        max_t=updates,
        grace_period=max(1, updates // 6),
        reduction_factor=3,
    )
    trainable = ray_tune.with_resources(
        ray_tune.with_parameters(_trial, config=config, updates=updates, seed=seed, trials=trials),
        {"cpu": 1},
    )
    # An interrupted search resumes when run again with the same arguments (Tune's records
    # under out/ray/search, the sampler's state included).
    experiment = root / "ray" / "search"
    arguments = {
        "config": config,
        "samples": samples,
        "updates": updates,
        "search": names,
        "seed": seed,
        "trials": trials,
        "sampler_seed": sampler_seed,
    }
    recorded = root / "ray" / "arguments.json"
    start, before_wall = time.perf_counter(), 0.0
    with cluster.session(address, workers):
        if ray_tune.Tuner.can_restore(str(experiment)):
            before = json.loads(recorded.read_text()) if recorded.is_file() else None
            if before != json.loads(json.dumps(arguments)):
                raise ValueError(
                    f"{root} holds a search with other arguments ({before}); resume it with "
                    "those, or use another --out"
                )
            tuner = ray_tune.Tuner.restore(str(experiment), trainable, resume_errored=True)
            if (root / "best.json").is_file():  # the time of the invocations before
                before_wall = json.loads((root / "best.json").read_text()).get("wall_time", 0.0)
        else:
            recorded.parent.mkdir(parents=True, exist_ok=True)
            recorded.write_text(json.dumps(arguments, indent=2))
            tuner = ray_tune.Tuner(
                trainable,
                tune_config=ray_tune.TuneConfig(
                    search_alg=searcher, scheduler=scheduler, num_samples=samples
                ),
                run_config=ray_tune.RunConfig(
                    name="search", storage_path=str(root / "ray"), verbose=1 if progress else 0
                ),
            )
        grid = tuner.fit()
    wall = before_wall + time.perf_counter() - start
    rows = []
    # Samples in the order they were drawn (Tune numbers its trial folders so; the grid's own
    # order changes when a search is restored), so sample 0 is the defaults.
    for result in sorted(grid, key=_sample_number):
        metrics = result.metrics or {}
        params = {n: result.config.get(n) for n in names if n in result.config}
        rows.append(
            {
                "trial": _sample_number(result),
                **{n: params.get(n) for n in names},
                "updates": metrics.get("update", 0),
                "validation_success": metrics.get("validation_success"),
                "objective": metrics.get("objective"),
                "eval_success": metrics.get("eval_success"),
                "violations": metrics.get("violations"),
                "error": type(result.error).__name__ if result.error else "",
                "_params": params,
            }
        )
    _write(root, rows, names, config, updates, seed, trials, samples, wall)
    return root


def _sample_number(result: Any) -> int:
    """The draw order of a Tune result: its folder is ``<trainable>_<id>_<N>_<params>``, N
    counting from 1."""
    match = re.search(r"_[0-9a-f]{5,}_(\d+)_", Path(result.path).name)
    if match is None:
        raise RuntimeError(f"unexpected Ray Tune trial folder name: {result.path}")
    return int(match.group(1)) - 1


def _write(
    root: Path,
    rows: list[dict[str, Any]],
    names: Sequence[str],
    config: str,
    updates: int,
    seed: int,
    trials: int,
    samples: int,
    wall: float,
) -> None:
    columns = [
        "trial",
        *names,
        "updates",
        "validation_success",
        "objective",
        "eval_success",
        "violations",
        "error",
    ]
    with (root / "trials.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    evaluated = [r for r in rows if r["objective"] is not None]
    ranked = sorted(evaluated, key=lambda r: -r["objective"])
    lines = [
        f"{len(rows)} samples of {config}, {updates} updates each (training seed {seed}; "
        f"objective: success on {trials} tuning trials, -1 with a violation; "
        f"{len(evaluated)} trained to the end, the others stopped early by ASHA), "
        f"{wall / 60:.1f} min",
        "",
        "| " + " | ".join(columns) + " |",
        "|" + "---|" * len(columns),
    ]
    for row in ranked + [r for r in rows if r["objective"] is None]:
        lines.append("| " + " | ".join(_cell(row[c]) for c in columns) + " |")
    (root / "trials.md").write_text("\n".join(lines) + "\n")
    from tlshield.lab.plots.tuning import plot_trials

    plot_trials(rows, names, {n: SPACE[n][1] for n in names}, root / "trials.png")
    feasible = [r for r in ranked if r["objective"] >= 0]
    if not feasible:
        raise RuntimeError(
            f"{root}: no sample met the no-violation constraint to the end of training; "
            "see trials.md (more samples or updates?)"
        )
    best = feasible[0]
    record = {
        "config": config,
        "objective": best["objective"],
        "settings": to_settings(best["_params"], config),
        "searched": best["_params"],
        "trial": best["trial"],
        "samples": samples,
        "updates": updates,
        "seed": seed,
        "tune_trials": trials,
        "tune_seed": TUNE_SEED,
        "wall_time": wall,
    }
    (root / "best.json").write_text(json.dumps(record, indent=2) + "\n")


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.3g}"
    return str(value)
