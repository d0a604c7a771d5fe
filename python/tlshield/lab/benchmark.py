"""``tlshield benchmark flatworld``: tlshield on DeepLTL's FlatWorld formulas, beside the
published success rates of DeepLTL, GCRL-LTL and LTL2Action.

Per (configuration, formula, seed) a PPO agent is trained on ``tlshield/FlatWorld-v0`` with
that formula and shield configuration, through the same pipeline as ``tlshield train``
(:func:`tlshield.lab.training.prepare` and :func:`~tlshield.lab.training.learn`, preset
:data:`PRESET`), then evaluated on ``episodes`` episodes with the
stochastic policy (as published) and the CBF on in every configuration but ``rl`` (the
unshielded contrast row). Two rows need no training: the shield with a zero policy
(``tlshield-zero``) and with a uniformly random one (``tlshield-random``), so a reader sees
what the shield does alone. Training jobs run as Ray tasks (:mod:`tlshield.lab.cluster`).

The comparison is not like for like, and every table says so: DeepLTL learns one policy for
all formulas (15M steps, zero-shot) with no map and no model; tlshield trains one agent per
formula, and its shield knows the discs and the dynamics.

Seeds (:mod:`tlshield.lab.seeds`): training env ``i`` of seed ``s`` resets from ``train_seed(s) +
i``, evaluation episode ``k`` from ``eval_block_seed(s, k)`` and PPO takes ``learner_seed(s)``:
streams of ``SeedSequence(s)`` in disjoint ranges, the evaluation ones never used for tuning.
"""

from __future__ import annotations

import csv
import math
import time
from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from tlshield._removed import refuse
from tlshield.envs import FLATWORLD_ID
from tlshield.envs.params import FULL, check_config
from tlshield.lab import bench
from tlshield.lab.evaluation import Recorder, rollouts
from tlshield.lab.presets import PRESETS, updates_for
from tlshield.lab.seeds import check_block, check_seeds, eval_block_seed

#: The columns of ``flatworld.csv``.
COLUMNS = (
    "method",
    "task",
    "seed",
    "success_rate",
    "mean_steps",
    "violations",
    "box_exits",
    "train_violations",
    "train_steps",
)

#: The published numbers: Jackermeier & Abate, "DeepLTL: Learning to Efficiently Satisfy
#: Complex LTL Specifications for Multi-Task RL", ICLR 2025, Table (FlatWorld), 5 seeds x 500
#: episodes, stochastic policies; DeepLTL's mean steps of successful episodes in brackets.
#: Per-seed data: ``results/FlatWorld-v0.csv`` of github.com/mathiasj33/deep-ltl.
PUBLISHED_SOURCE = (
    "Jackermeier & Abate, DeepLTL (ICLR 2025), FlatWorld table; 5 seeds x 500 episodes, "
    "stochastic policy; one policy for all formulas, 15M steps, no map or model"
)
PUBLISHED: dict[str, dict[int, tuple[float, float | None]]] = {
    "DeepLTL": {
        1: (1.000, 79.7),
        2: (0.999, 52.8),
        3: (0.978, 71.8),
        4: (0.860, 43.9),
        5: (0.996, 37.0),
    },
    "GCRL-LTL": {
        1: (0.818, None),
        2: (0.000, None),
        3: (0.726, None),
        4: (0.725, None),
        5: (0.636, None),
    },
    "LTL2Action": {
        1: (0.999, None),
        2: (0.628, None),
        3: (0.714, None),
        4: (0.073, None),
        5: (0.562, None),
    },
}

#: Defaults of the command.
DEFAULT_CONFIGS = (FULL, "rl")
DEFAULT_SEEDS = (1, 2, 3)
DEFAULT_EPISODES = 500
DEFAULT_STEPS = 600_000

#: The PPO preset every formula trains with (:data:`tlshield.lab.presets.PRESETS`): no
#: per-formula settings.
PRESET = "flatworld"
#: The discount of that preset (the progress reward is sized for it).
GAMMA = PRESETS[PRESET]["ppo"]["gamma"]

Policy = Callable[[np.ndarray, np.random.Generator], np.ndarray]


def run_episodes(
    formula: str,
    config: str,
    policy: Policy,
    seed: int,
    episodes: int,
    batch: int = 50,
    **overrides: Any,
) -> dict[str, Any]:
    """Evaluation: ``episodes`` episodes (``batch`` side by side, one policy call per step,
    through :func:`tlshield.lab.evaluation.rollouts`), CBF on unless ``config == "rl"``.
    Returns the success rate, the mean steps of successful episodes (DeepLTL's measure), trap
    entries (``violations``: the formula's safety part broken), box exits and a few paths for
    the figure. ``overrides``: FlatWorld settings."""
    rng = np.random.default_rng(eval_block_seed(seed, 0))
    make_kwargs = {"formula": formula, "gamma": GAMMA, "disable_env_checker": True, **overrides}
    ended: list[dict[str, Any]] = []  # every episode's outcome, in the order the episodes ended
    for start in range(0, episodes, batch):
        seeds = [eval_block_seed(seed, k) for k in range(start, min(start + batch, episodes))]
        outcomes = rollouts(
            config,
            make_kwargs,
            lambda obs: policy(obs, rng),
            seeds,
            FLATWORLD_ID,
            evaluation=config != "rl",
            recorders=[EpisodeEnd()],
        )
        # A batch's episodes end by step, and by index within a step (a stable sort).
        ended += sorted(outcomes, key=lambda o: o["steps"])
    steps = [o["steps"] for o in ended if o["success"]]
    return {
        "success_rate": len(steps) / episodes,
        "mean_steps": float(np.mean(steps)) if steps else math.nan,
        "violations": sum(o["trap_entry"] for o in ended),
        "box_exits": sum(o["box_exit"] for o in ended),
        "paths": [(o["path"], o["success"]) for o in ended[:12]],
    }


class EpisodeEnd(Recorder):
    """What the benchmark reads from a FlatWorld episode's last step: whether it entered the
    trap, whether it left the square, and its path."""

    def end(self, trial: int, env: Any, info: dict[str, Any], terminated: bool) -> dict[str, Any]:
        return {
            "trap_entry": int(info["trap"] and terminated),
            "box_exit": int(info["box_exit"]),
            "path": np.asarray(env.unwrapped.path),
        }


def zero_policy(obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The shield alone: the agent proposes nothing."""
    return np.zeros((len(obs), 2))


def random_policy(obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Uniform actions in ``[-1, 1]^2``."""
    return rng.uniform(-1.0, 1.0, size=(len(obs), 2))


def training_counts(folder: Path) -> dict[str, int]:
    """A finished training run's counts from its ``metrics.csv``: failures (trap entries plus
    box exits, FlatWorld's ``info["violation"]``) and environment steps."""
    with (folder / "metrics.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    failures = sum(int(float(r["trap_entries"])) + int(float(r["violations"])) for r in rows)
    return {"train_violations": failures, "train_steps": int(rows[-1]["timesteps"])}


def job(
    formula: str, k: int, config: str, seed: int, steps: int, episodes: int, folder: Path
) -> None:
    """One (config, formula, seed): train through :func:`tlshield.lab.training.prepare` and
    :func:`~tlshield.lab.training.learn` into ``folder`` (a run folder: ``run.json``,
    ``metrics.csv``, the model), evaluate the trained policy, and write ``result.json`` and
    ``paths.npz`` beside them (a Ray task)."""
    from tlshield.lab.training import learn, prepare

    start = time.perf_counter()
    run = prepare(
        config,
        seed,
        updates_for(steps, PRESET),
        folder,
        progress=False,
        preset=PRESET,
        env=FLATWORLD_ID,
        formula=formula,
    )
    learn(run)
    model = run.model

    def policy(obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return model.predict(obs, deterministic=False)[0]

    result = run_episodes(formula, config, policy, seed, episodes)
    counts = training_counts(folder)
    _write(
        folder, f"tlshield-{config}", formula, k, seed, result, counts, time.perf_counter() - start
    )


def _write(
    folder: Path,
    method: str,
    formula: str,
    k: int,
    seed: int,
    result: dict[str, Any],
    counts: dict[str, int],
    wall: float,
) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    paths = result.pop("paths")
    np.savez(
        folder / "paths.npz",
        **{f"path{i}": p for i, (p, _) in enumerate(paths)},
        success=np.array([ok for _, ok in paths], dtype=bool),
    )
    row = {"method": method, "task": formula, "formula": k, "seed": seed, **result, **counts}
    row["wall_time"] = wall
    bench.write_result(folder, row)  # last: the job is finished


def flatworld(
    out: str | Path,
    *,
    formulas: Sequence[str] | None = None,
    configs: Sequence[str] = DEFAULT_CONFIGS,
    seeds: Sequence[int] = DEFAULT_SEEDS,
    episodes: int = DEFAULT_EPISODES,
    steps: int = DEFAULT_STEPS,
    address: str | None = None,
    workers: int | None = None,
    progress: bool = True,
) -> Path:
    """Runs the benchmark into ``out`` (resumable: finished jobs are kept) and writes
    ``flatworld.csv``, ``flatworld.md`` and ``flatworld_paths.png``."""
    from tlshield.envs.flatworld import FORMULAS, flatworld_spec

    formulas = list(formulas or FORMULAS)
    for f in formulas:
        flatworld_spec(f)  # a formula over unknown colours fails here, before any job
    for c in configs:
        check_config(c)
    check_block(episodes, "episodes")
    if not (isinstance(steps, int) and steps > 0):
        raise ValueError(f"steps = {steps!r}: expected a positive integer")
    check_seeds(seeds)
    out = Path(out)
    runs = out / "runs"
    runs.mkdir(parents=True, exist_ok=True)
    # The shield alone: cheap, run here.
    for k, f in enumerate(formulas, 1):
        for s in seeds:
            for name, policy in (("zero", zero_policy), ("random", random_policy)):
                folder = runs / f"{name}-f{k}-s{s}"
                if not bench.is_finished(folder):
                    t0 = time.perf_counter()
                    result = run_episodes(f, FULL, policy, s, episodes)
                    counts = {"train_violations": 0, "train_steps": 0}
                    _write(
                        folder,
                        f"tlshield-{name}",
                        f,
                        k,
                        s,
                        result,
                        counts,
                        time.perf_counter() - t0,
                    )
    jobs = {
        runs / f"{c}-f{k}-s{s}": partial(job, f, k, c, s, steps, episodes)
        for c in configs
        for k, f in enumerate(formulas, 1)
        for s in seeds
    }
    return bench.run(report(formulas), out, jobs, address, workers, progress)


def report(formulas: Sequence[str]) -> bench.Benchmark:
    """The benchmark as data for :mod:`tlshield.lab.bench`: ``flatworld.csv`` (:data:`COLUMNS`),
    ``flatworld.md`` (:func:`markdown`) and ``flatworld_paths.png``."""
    return bench.Benchmark(
        name="flatworld",
        columns=COLUMNS,
        order=lambda r: (r["method"], r["formula"], r["seed"]),
        markdown=partial(markdown, formulas=formulas),
        figure=partial(_figure, formulas=formulas),
        csv_row=lambda r: {**r, "mean_steps": _num(r["mean_steps"])},
    )


def _num(x: float) -> str:
    return "" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.1f}"


def markdown(rows: list[dict[str, Any]], formulas: Sequence[str]) -> str:
    """The comparison table: per formula and method, the success rate (mean over seeds, and
    each seed), mean steps, and the evaluation and training safety counts."""
    methods = list(dict.fromkeys(r["method"] for r in rows))
    lines = [
        "tlshield trains one agent per formula, and its shield knows the discs and the dynamics; "
        "DeepLTL learns one policy for all formulas (15M steps, zero-shot) with no map and no "
        "model. Published rows: " + PUBLISHED_SOURCE + ".",
        "",
        "| # | method | success (mean) | per seed | steps | violations | box exits "
        "| train violations | train steps |",
        "|---|---|---:|---|---:|---:|---:|---:|---:|",
    ]
    for k, f in enumerate(formulas, 1):
        for m in methods:
            mine = [r for r in rows if r["method"] == m and r["task"] == f]
            if not mine:
                continue
            rates = [r["success_rate"] for r in mine]
            steps = [
                r["mean_steps"]
                for r in mine
                if r["mean_steps"] is not None and not math.isnan(r["mean_steps"])
            ]
            per_seed = " ".join(f"{r['success_rate']:.3f}" for r in mine)
            lines.append(
                f"| {k} | {m} | {np.mean(rates):.3f} | {per_seed} | "
                f"{_num(float(np.mean(steps)) if steps else math.nan)} | "
                f"{sum(r['violations'] for r in mine)} | {sum(r['box_exits'] for r in mine)} | "
                f"{sum(r['train_violations'] for r in mine)} | {mine[0]['train_steps']} |"
            )
        published = formulas[k - 1] == _published_formula(k)
        for name, table in PUBLISHED.items():
            if published:
                rate, steps_ = table[k]
                lines.append(
                    f"| {k} | {name} (published) | {rate:.3f} | | {_num(steps_)} | | | | |"
                )
    lines += ["", "Formulas:", ""]
    lines += [f"{k}. `{f}`" for k, f in enumerate(formulas, 1)]
    return "\n".join(lines) + "\n"


def _published_formula(k: int) -> str | None:
    from tlshield.envs.flatworld import FORMULAS

    return FORMULAS[k - 1] if k <= len(FORMULAS) else None


def _figure(out: Path, rows: list[dict[str, Any]], formulas: Sequence[str]) -> None:
    from tlshield.envs.flatworld import CIRCLES
    from tlshield.lab.plots.flatworld import plot_paths

    panels = []
    for k, f in enumerate(formulas, 1):
        method = "tlshield-rl_cbf_clf"
        folder = next(iter(sorted((out / "runs").glob(f"rl_cbf_clf-f{k}-s*"))), None)
        if folder is None:
            method, folder = (
                "tlshield-zero",
                next(iter(sorted((out / "runs").glob(f"zero-f{k}-s*"))), None),
            )
        if folder is None:
            continue
        data = np.load(folder / "paths.npz")
        ok = list(data["success"])
        paths = [data[f"path{i}"] for i in range(len(ok))]
        seed = folder.name.rsplit("-s", 1)[1]
        title = f"{k}. {f}\n({method}, seed {seed}, 8 evaluation episodes)"
        panels.append((title, paths[:8], ok[:8]))
    if panels:
        plot_paths(panels, out / "flatworld_paths.png", CIRCLES)


#: Names removed in 0.4, refused with a message naming what replaced them.
__getattr__ = refuse(
    __name__,
    {
        "read_rows": "tlshield.lab.bench.read_rows(bench, out) with bench = "
        "tlshield.lab.benchmark.report(formulas)",
        "write_report": "tlshield.lab.bench.write_report(bench, out) with bench = "
        "tlshield.lab.benchmark.report(formulas)",
    },
)
