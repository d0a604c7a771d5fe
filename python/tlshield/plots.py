"""Figures and a results table from a results folder (``tlshield reproduce`` / ``tlshield plot``).

A results folder holds one run folder per configuration and seed (``<config>_s<seed>/``, as
written by :func:`tlshield.training.train` and :func:`tlshield.training.evaluate`):
``config.json``, ``metrics.csv`` (one row per PPO update), and after evaluation
``evaluation.json`` and ``trajectories.npz``. Any of the last three may be missing, empty or
partial (an interrupted run); the figures and the table leave out what is not there.

:func:`plot_all` writes the figures of the paper's case study (Li & Belta, Figs. 6.2.1-6.2.5)
as 150 dpi PNGs:

* ``learning_curves.png``: mean discounted episode return per PPO update;
* ``min_constraints.png``: the smallest channel barrier values ``h_c1``, ``h_c2`` per update;
* ``min_obstacle_distance.png``: the smallest distance to an obstacle per update;
* ``success_rates.png``: evaluation success rate per configuration;
* ``trajectories.png``: one common evaluation trial, one panel per configuration;
* ``task_automaton.png``: the automaton of the task (Graphviz ``dot`` if installed).

Curves show the mean over seeds with a band of +- one standard deviation (population standard
deviation, ``ddof=0``, as everywhere in this module). Each configuration keeps its colour in
every figure (:data:`CONFIG_COLORS`).

matplotlib is imported lazily and only through the Agg canvas (never :mod:`matplotlib.pyplot`),
so plotting touches no global state and needs no display.
"""

from __future__ import annotations

import csv
import json
import math
import shutil
import subprocess
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tlshield.envs.channel import (
    CONFIGS,
    GOAL_DIMS,
    OBSTACLE_DIMS,
    STATE_DIM,
    ChannelConfig,
    channel_task_spec,
)
from tlshield.training import METRIC_COLUMNS

__all__ = [
    "CONFIG_COLORS",
    "CONFIG_LABELS",
    "FIGURES",
    "TABLE_COLUMNS",
    "Run",
    "load_results",
    "plot_all",
    "results_table",
]

#: The colour of each configuration, the same in every figure.
CONFIG_COLORS = {
    "rl": "#d62728",
    "rl_cbf": "#1f77b4",
    "rl_clf": "#ff7f0e",
    "rl_cbf_clf": "#2ca02c",
}
#: Colours of configurations not in :data:`CONFIG_COLORS`, in order of appearance.
_EXTRA_COLORS = ("#8c564b", "#e377c2", "#17becf", "#bcbd22", "#7f7f7f")
#: Display names of the configurations.
CONFIG_LABELS = {
    "rl": "RL",
    "rl_cbf": "RL + CBF",
    "rl_clf": "RL + CLF",
    "rl_cbf_clf": "RL + CBF + CLF",
}
#: File names written by :func:`plot_all`, in order.
FIGURES = (
    "learning_curves.png",
    "min_constraints.png",
    "min_obstacle_distance.png",
    "success_rates.png",
    "trajectories.png",
    "task_automaton.png",
)
#: Header of :func:`results_table`.
TABLE_COLUMNS = (
    "config",
    "seeds",
    "updates",
    "train violations",
    "trap entries",
    "relaxed / failed QPs",
    "return, first 20%",
    "return, last 10%",
    "eval success rate",
    "eval collisions",
    "eval violation steps",
)

DPI = 150
#: Trajectory figure: the scene's goal and obstacle styles (not colours of a configuration).
_GOAL_COLOR = "#9467bd"
_OBSTACLE_COLOR = "0.35"
_CHANNEL_COLOR = "#1f77b4"
_MISSING = "—"
#: Typographic symbols of figure labels (escaped: they look like ASCII letters in source).
_MINUS, _AND, _OR, _NOT = "\u2212", "\u2227", "\u2228", "\u00ac"


# --- loading ---------------------------------------------------------------------------------


@dataclass
class Run:
    """One run folder of a results folder."""

    #: The run folder.
    path: Path
    #: Configuration name ("rl", "rl_cbf", "rl_clf", "rl_cbf_clf").
    config: str
    #: Training seed.
    seed: int
    #: metrics.csv by column (:data:`tlshield.training.METRIC_COLUMNS`), one value per update;
    #: every array is empty when the run has no complete row yet.
    metrics: dict[str, NDArray[np.float64]]
    #: evaluation.json, or None when the run was not evaluated.
    evaluation: dict[str, Any] | None
    #: ``(starts, paths)`` of trajectories.npz: the ``(trials, 13)`` initial states and one
    #: ``(length, 2)`` xy path per trial; None when missing.
    trajectories: tuple[NDArray[np.float64], list[NDArray[np.float64]]] | None
    #: The whole config.json.
    record: dict[str, Any] = field(default_factory=dict)
    #: One ``(length, 4)`` path of the two obstacle centres per trial (None when missing).
    obstacle_paths: list[NDArray[np.float64]] | None = None

    @property
    def updates(self) -> int:
        """Number of complete metric rows (PPO updates)."""
        return len(self.metrics["update"])

    @property
    def env(self) -> ChannelConfig:
        """The environment constants the run trained with (defaults for missing fields)."""
        return _env_config(self.record)


def _tuples(value: Any) -> Any:
    """JSON lists back to the (nested) tuples of :class:`ChannelConfig`."""
    return tuple(_tuples(v) for v in value) if isinstance(value, list) else value


def _env_config(record: dict[str, Any]) -> ChannelConfig:
    known = ChannelConfig.__dataclass_fields__
    env = record.get("env")
    values = {k: _tuples(v) for k, v in env.items() if k in known} if isinstance(env, dict) else {}
    try:
        return ChannelConfig(**values)
    except TypeError:  # pragma: no cover - a config.json from an incompatible version
        return ChannelConfig()


def _read_metrics(path: Path) -> dict[str, NDArray[np.float64]]:
    """metrics.csv by column; tolerates a missing or empty file and a last row cut short."""
    rows: list[list[float]] = []
    if path.is_file():
        with path.open(newline="") as f:
            for row in csv.DictReader(f):
                try:
                    rows.append([float(row[c]) for c in METRIC_COLUMNS])
                except (KeyError, TypeError, ValueError):
                    continue  # an incomplete row (the run was stopped while writing it)
    table = np.array(rows, dtype=np.float64).reshape(len(rows), len(METRIC_COLUMNS))
    return {c: table[:, i].copy() for i, c in enumerate(METRIC_COLUMNS)}


def _read_json(path: Path) -> dict[str, Any] | None:
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as err:
        warnings.warn(f"{path}: unreadable ({err}); ignoring it", RuntimeWarning, stacklevel=3)
        return None
    return data if isinstance(data, dict) else None


def _read_trajectories(
    path: Path,
) -> tuple[NDArray[np.float64], list[NDArray[np.float64]]] | None:
    if not path.is_file():
        return None
    try:
        with np.load(path) as data:
            starts = np.asarray(data["starts"], dtype=np.float64)
            lengths = np.asarray(data["lengths"], dtype=np.int64)
            flat = np.asarray(data["paths"], dtype=np.float64)
    except (OSError, ValueError, KeyError) as err:
        warnings.warn(f"{path}: unreadable ({err}); ignoring it", RuntimeWarning, stacklevel=3)
        return None
    if (
        starts.ndim != 2
        or starts.shape[1] < STATE_DIM
        or lengths.shape != (len(starts),)
        or flat.ndim != 2
        or flat.shape[1] != 2
        or int(lengths.sum()) != len(flat)
    ):
        warnings.warn(f"{path}: inconsistent arrays; ignoring it", RuntimeWarning, stacklevel=3)
        return None
    paths = np.split(flat, np.cumsum(lengths)[:-1]) if len(lengths) else []
    return starts, list(paths)


def _read_obstacle_paths(path: Path, lengths: list[int]) -> list[NDArray[np.float64]] | None:
    if not path.is_file():
        return None
    try:
        with np.load(path) as data:
            if "obstacle_paths" not in data:
                return None
            flat = np.asarray(data["obstacle_paths"], dtype=np.float64)
    except (OSError, ValueError) as err:
        warnings.warn(f"{path}: unreadable ({err}); ignoring it", RuntimeWarning, stacklevel=3)
        return None
    if flat.ndim != 2 or flat.shape[1] != 4 or len(flat) != sum(lengths):
        return None
    return list(np.split(flat, np.cumsum(lengths)[:-1])) if lengths else []


def _load_run(folder: Path) -> Run | None:
    record = _read_json(folder / "config.json")
    if record is None or "config" not in record:
        return None
    try:
        seed = int(record.get("seed", 0))
    except (TypeError, ValueError):
        seed = 0
    trajectories = _read_trajectories(folder / "trajectories.npz")
    lengths = [len(p) for p in trajectories[1]] if trajectories else []
    return Run(
        path=folder,
        config=str(record["config"]),
        seed=seed,
        metrics=_read_metrics(folder / "metrics.csv"),
        evaluation=_read_json(folder / "evaluation.json"),
        trajectories=trajectories,
        record=record,
        obstacle_paths=_read_obstacle_paths(folder / "trajectories.npz", lengths),
    )


def _config_order(config: str) -> tuple[int, str]:
    known = list(CONFIGS)
    return (known.index(config), "") if config in known else (len(known), config)


def load_results(results: str | Path) -> dict[str, list[Run]]:
    """The runs of a results folder: configuration -> runs sorted by seed, configurations in
    the paper's order ("rl", "rl_cbf", "rl_clf", "rl_cbf_clf", then any other).

    A run is a sub-folder with a ``config.json`` (``results`` itself counts when it is a run
    folder). Raises FileNotFoundError when the folder does not exist or holds no run.
    """
    root = Path(results)
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: no such results folder")
    folders = [root] if (root / "config.json").is_file() else sorted(root.iterdir())
    runs = [run for folder in folders if folder.is_dir() and (run := _load_run(folder))]
    if not runs:
        raise FileNotFoundError(
            f"{root}: no runs found (expected sub-folders <config>_s<seed>/ with a config.json, "
            "as written by `tlshield reproduce --out`)"
        )
    grouped: dict[str, list[Run]] = {}
    for run in sorted(runs, key=lambda r: (_config_order(r.config), r.seed, r.path.name)):
        grouped.setdefault(run.config, []).append(run)
    return grouped


# --- statistics ------------------------------------------------------------------------------


def _color(config: str, configs: Sequence[str]) -> str:
    if config in CONFIG_COLORS:
        return CONFIG_COLORS[config]
    others = [c for c in configs if c not in CONFIG_COLORS]
    return _EXTRA_COLORS[others.index(config) % len(_EXTRA_COLORS)]


def _label(config: str) -> str:
    return CONFIG_LABELS.get(config, config)


def _nan_mean_std(values: NDArray[np.float64], axis: int = 0) -> tuple[NDArray, NDArray]:
    """Mean and (population) std over the finite values along ``axis``; NaN where none."""
    finite = np.isfinite(values)
    count = finite.sum(axis=axis)
    filled = np.where(finite, values, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = filled.sum(axis=axis) / count
        centred = np.where(finite, values - np.expand_dims(mean, axis), 0.0)
        std = np.sqrt((centred**2).sum(axis=axis) / count)
    return mean, std


def _curve(
    runs: Sequence[Run], column: str
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]] | None:
    """(updates, mean, std) of ``column`` over the runs, aligned by update number; None when
    no run has a metric row."""
    used = [r for r in runs if r.updates > 0]
    if not used:
        return None
    last = int(max(np.nanmax(r.metrics["update"]) for r in used))
    table = np.full((len(used), last), np.nan)
    for i, run in enumerate(used):
        index = run.metrics["update"].astype(np.int64) - 1
        ok = (index >= 0) & (index < last)
        table[i, index[ok]] = run.metrics[column][ok]
    mean, std = _nan_mean_std(table)
    return np.arange(1, last + 1, dtype=np.float64), mean, std


def _seed_stat(values: Sequence[float]) -> tuple[float, float] | None:
    finite = [v for v in values if math.isfinite(v)]
    if not finite:
        return None
    return float(np.mean(finite)), float(np.std(finite))


def _fraction_mean(values: NDArray[np.float64], fraction: float, first: bool) -> float:
    """Mean of the finite values among the first (or last) ``fraction`` of ``values``."""
    if len(values) == 0:
        return math.nan
    k = max(1, math.ceil(fraction * len(values)))
    part = values[:k] if first else values[-k:]
    part = part[np.isfinite(part)]
    return float(np.mean(part)) if len(part) else math.nan


# --- the results table -----------------------------------------------------------------------


def _pm(stat: tuple[float, float] | None, digits: int) -> str:
    if stat is None:
        return _MISSING
    mean, std = stat
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


def _trials_note(evaluations: Sequence[dict[str, Any]]) -> str:
    trials = [int(e.get("trials", 0)) for e in evaluations]
    if len(set(trials)) == 1:
        return f"{len(trials)} x {trials[0]} trials"
    return f"{sum(trials)} trials"


def results_table(results: str | Path) -> str:
    """A Markdown table of a results folder, one row per configuration (columns:
    :data:`TABLE_COLUMNS`).

    Training columns sum over every update of every seed (violations are environment steps
    outside the channel; relaxed / failed count shield QPs). Returns are the mean discounted
    episode return over the first 20% and the last 10% of each seed's updates, then mean +- std
    over seeds. Evaluation columns: success rate mean +- std over the evaluated seeds (with the
    number of trials), collisions out of all trials, and the steps outside the channel.
    """
    groups = load_results(results)
    lines = [
        "| " + " | ".join(TABLE_COLUMNS) + " |",
        "|" + "|".join(["---"] + ["---:"] * (len(TABLE_COLUMNS) - 1)) + "|",
    ]
    for config, runs in groups.items():
        counts = sorted({r.updates for r in runs})
        updates = str(counts[0]) if len(counts) == 1 else f"{counts[0]}-{counts[-1]}"
        trained = [r for r in runs if r.updates > 0]

        def total(column: str, trained: list[Run] = trained) -> str:
            if not trained:
                return _MISSING
            return str(int(sum(np.nansum(r.metrics[column]) for r in trained)))

        first = _seed_stat([_fraction_mean(r.metrics["return_mean"], 0.2, True) for r in trained])
        final = _seed_stat([_fraction_mean(r.metrics["return_mean"], 0.1, False) for r in trained])
        evaluations = [r.evaluation for r in runs if r.evaluation is not None]
        if evaluations:
            rate = _seed_stat([float(e.get("success_rate", math.nan)) for e in evaluations])
            success = f"{_pm(rate, 2)} ({_trials_note(evaluations)})"
            trials = sum(int(e.get("trials", 0)) for e in evaluations)
            collisions = f"{sum(int(e.get('collisions', 0)) for e in evaluations)} / {trials}"
            violation_steps = str(sum(int(e.get("violation_steps", 0)) for e in evaluations))
        else:
            success = collisions = violation_steps = _MISSING
        relaxed_failed = f"{total('relaxed')} / {total('failed')}" if trained else _MISSING
        cells = (
            config,
            ", ".join(str(r.seed) for r in runs),
            updates,
            total("violations"),
            total("trap_entries"),
            relaxed_failed,
            _pm(first, 1),
            _pm(final, 1),
            success,
            collisions,
            violation_steps,
        )
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


# --- figures ---------------------------------------------------------------------------------


def _figure(width: float, height: float) -> Any:
    """A Figure on its own Agg canvas, with constrained layout."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Any, path: Path) -> Path:
    fig.savefig(path, dpi=DPI, facecolor="white")
    return path


def _no_data(ax: Any, text: str) -> None:
    ax.text(
        0.5,
        0.5,
        text,
        transform=ax.transAxes,
        ha="center",
        va="center",
        fontsize=11,
        color="0.4",
    )


def _training_of(groups: dict[str, list[Run]]) -> tuple[int, float]:
    """Environment steps per update and the discount of the runs (their config.json)."""
    record = next(iter(groups.values()))[0].record
    ppo = record.get("ppo", {})
    steps = int(record.get("n_envs", 5)) * int(ppo.get("n_steps", 200))
    return steps, float(ppo.get("gamma", 0.99))


def _update_axis(ax: Any, steps: int) -> None:
    from matplotlib.ticker import MaxNLocator

    ax.set_xlabel(f"PPO update (1 update = {steps} environment steps)")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.grid(True, color="0.9", linewidth=0.6)
    ax.set_axisbelow(True)


def _plot_band(ax: Any, runs: Sequence[Run], column: str, color: str, label: str) -> bool:
    """Mean +- std of ``column`` over the runs; False when there is nothing to draw."""
    curve = _curve(runs, column)
    if curve is None or not np.any(np.isfinite(curve[1])):
        return False
    x, mean, std = curve
    n = sum(1 for r in runs if r.updates > 0)
    marker = "o" if len(x) <= 25 else None
    ax.plot(
        x,
        mean,
        color=color,
        lw=1.6 if len(x) <= 50 else 1.2,
        marker=marker,
        ms=3.5,
        label=f"{label} ({n} seed{'s' if n != 1 else ''})",
    )
    ax.fill_between(x, mean - std, mean + std, color=color, alpha=0.2, lw=0)
    return True


def _curves_figure(
    groups: dict[str, list[Run]],
    columns: Sequence[tuple[str, str]],
    ylabel: str,
    title: str,
    path: Path,
    hlines: Sequence[tuple[float, str, str]] = (),
    shade_below: float | None = None,
    ymin: float | None = None,
) -> Path:
    """One panel per ``(column, panel title)``: mean +- std over seeds per configuration."""
    configs = list(groups)
    fig = _figure(7.5 if len(columns) == 1 else 12.0, 5.2)
    # Panels keep their own y range: one constraint's violations must not flatten the other.
    axes = fig.subplots(1, len(columns), squeeze=False)[0]
    drawn = False
    for ax, (column, panel) in zip(axes, columns, strict=True):
        any_curve = False
        for config, runs in groups.items():
            any_curve |= _plot_band(ax, runs, column, _color(config, configs), _label(config))
        drawn |= any_curve
        if not any_curve:
            _no_data(ax, "no training metrics yet")
        for y, style, label in hlines:
            ax.axhline(y, color="black", lw=1.0, ls=style, label=label, zorder=1)
        if shade_below is not None and any_curve:
            ax.autoscale_view()
            lo, hi = ax.get_ylim()
            if lo < shade_below:
                ax.axhspan(lo, shade_below, color="#d62728", alpha=0.06, lw=0, zorder=0)
                ax.set_ylim(lo, hi)
        if ymin is not None and any_curve:
            ax.set_ylim(bottom=ymin)
        _update_axis(ax, _training_of(groups)[0])
        if len(columns) > 1:
            ax.set_title(panel)
    axes[0].set_ylabel(ylabel)
    if drawn:
        handles, labels = axes[0].get_legend_handles_labels()
        # Below the panels: noisy curves leave no free corner for a legend inside.
        ncols = min(len(labels), 6) if len(columns) > 1 else (3 if len(labels) > 4 else 2)
        fig.legend(handles, labels, loc="outside lower center", ncols=ncols, fontsize=9)
    fig.suptitle(title)
    return _save(fig, path)


def _env_of(groups: dict[str, list[Run]]) -> ChannelConfig:
    return next(iter(groups.values()))[0].env


def _plot_learning_curves(groups: dict[str, list[Run]], path: Path) -> Path:
    return _curves_figure(
        groups,
        [("return_mean", "")],
        rf"discounted episode return ($\gamma$ = {_training_of(groups)[1]:g})",
        "Learning curves: mean ± std over seeds",
        path,
    )


def _plot_min_constraints(groups: dict[str, list[Run]], path: Path) -> Path:
    return _curves_figure(
        groups,
        [
            ("min_h_c1", f"channel constraint c1: h = x {_MINUS} y + w"),
            ("min_h_c2", f"channel constraint c2: h = y {_MINUS} x + w"),
        ],
        "smallest h in the update [m]",
        "Smallest channel barrier value per update (below 0 = outside the channel)",
        path,
        hlines=[(0.0, "-", "h = 0 (violation below)")],
        shade_below=0.0,
    )


def _plot_min_obstacle_distance(groups: dict[str, list[Run]], path: Path) -> Path:
    env = _env_of(groups)
    return _curves_figure(
        groups,
        [("min_obstacle_distance", "")],
        "smallest distance to an obstacle [m]",
        "Smallest obstacle distance per update (mean ± std over seeds)",
        path,
        hlines=[
            (env.obstacle_radius, "-", f"collision distance ({env.obstacle_radius:g} m)"),
            (env.safe_distance, ":", f"reward safe distance ({env.safe_distance:g} m)"),
        ],
        shade_below=env.obstacle_radius,
        ymin=0.0,
    )


def _plot_success_rates(groups: dict[str, list[Run]], path: Path) -> Path:
    configs = list(groups)
    fig = _figure(max(6.0, 1.6 * len(configs) + 1.5), 5.0)
    ax = fig.subplots()
    rng = np.random.default_rng(0)  # jitter of the seed dots, deterministic
    ticks = []
    for i, (config, runs) in enumerate(groups.items()):
        color = _color(config, configs)
        evaluations = [r.evaluation for r in runs if r.evaluation is not None]
        rates = [float(e.get("success_rate", math.nan)) for e in evaluations]
        stat = _seed_stat(rates)
        if stat is None:
            ax.text(i, 0.03, "no evaluation", ha="center", va="bottom", rotation=90, color="0.4")
            ticks.append(_label(config))
            continue
        mean, std = stat
        err = [[mean - max(mean - std, 0.0)], [min(mean + std, 1.0) - mean]]
        ax.bar(i, mean, width=0.6, color=color, alpha=0.75, edgecolor=color, lw=1.2)
        ax.errorbar(i, mean, yerr=err, color="black", capsize=6, lw=1.2)
        finite = [r for r in rates if math.isfinite(r)]
        jitter = rng.uniform(-0.12, 0.12, size=len(finite))
        ax.scatter(
            i + jitter,
            finite,
            s=22,
            color="white",
            edgecolor="black",
            lw=0.9,
            zorder=3,
            clip_on=False,
        )
        ticks.append(f"{_label(config)}\n{mean:.2f} ± {std:.2f}\n({_trials_note(evaluations)})")
    ax.set_xticks(range(len(configs)), ticks, fontsize=8.5)
    ax.set_xlim(-0.6, len(configs) - 0.4)
    ax.set_ylim(0.0, 1.0)
    ax.set_ylabel("evaluation success rate (fraction of trials)")
    ax.grid(True, axis="y", color="0.9", linewidth=0.6)
    ax.set_axisbelow(True)
    ax.set_title(
        "Evaluation success rate (CBF on)\nbars: mean ± std over seeds; dots: one seed each"
    )
    return _save(fig, path)


def _trial_outcome(run: Run, start: NDArray[np.float64], path: NDArray[np.float64]) -> str:
    """How the trial ended, as the evaluation recorded it (success, collision or time-out).
    Older runs without per-trial records: re-derived from the path with the obstacles as they
    were at the start."""
    env = run.env
    outcomes = (run.evaluation or {}).get("outcomes")
    if outcomes:
        first = outcomes[0]
        steps = first.get("steps", len(path) - 1)
        if first.get("success"):
            return f"success in {steps} steps"
        if first.get("collision"):
            return f"collision at step {steps}"
        return f"time-out ({steps} steps)"
    traj = np.tile(start[:STATE_DIM], (len(path), 1))
    traj[:, :2] = path
    steps = len(path) - 1
    try:
        accepted = channel_task_spec(env.half_width, env.goal_radius).automaton().accepts(traj)
    except Exception:  # pragma: no cover - the outcome is only a caption
        return f"{steps} steps"
    if accepted:
        return f"success in {steps} steps"
    if steps < env.horizon:
        return f"collision at step {steps}"
    return f"time-out ({steps} steps)"


def _trajectory_run(runs: Sequence[Run]) -> Run | None:
    """Seed 0's run, else the lowest seed's, among the runs with trajectories."""
    evaluated = [r for r in runs if r.trajectories is not None and len(r.trajectories[1])]
    if not evaluated:
        return None
    return next((r for r in evaluated if r.seed == 0), evaluated[0])


def _draw_channel(ax: Any, half_width: float, lo: float, hi: float) -> None:
    from matplotlib.patches import Polygon

    w = half_width
    band = [(lo, lo - w), (hi, hi - w), (hi, hi + w), (lo, lo + w)]
    ax.add_patch(
        Polygon(band, closed=True, facecolor=_CHANNEL_COLOR, alpha=0.1, lw=0, label="channel")
    )
    for offset in (w, -w):
        ax.plot([lo, hi], [lo + offset, hi + offset], color=_CHANNEL_COLOR, lw=0.9)


def _plot_trajectories(groups: dict[str, list[Run]], path: Path) -> Path:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle, Patch

    configs = list(groups)
    chosen = {c: _trajectory_run(runs) for c, runs in groups.items()}
    env = _env_of(groups)
    ncols = min(2, len(configs))
    nrows = math.ceil(len(configs) / ncols)
    fig = _figure(5.2 * ncols, 5.0 * nrows + 0.6)
    axes = fig.subplots(nrows, ncols, squeeze=False, sharex=True, sharey=True).ravel()

    # Common limits: everything drawn in any panel, padded, square, within the arena.
    points = [np.zeros((1, 2))]
    for run in chosen.values():
        if run is None or run.trajectories is None:
            continue
        start, trial = run.trajectories[0][0], run.trajectories[1][0]
        goals = np.array([start[list(d)] for d in GOAL_DIMS])
        points += [trial, goals - env.goal_radius, goals + env.goal_radius]
    cloud = np.vstack(points)
    lo_xy, hi_xy = cloud.min(axis=0) - 0.8, cloud.max(axis=0) + 0.8
    side = float(max(hi_xy - lo_xy))
    centre = (lo_xy + hi_xy) / 2
    a_lo, a_hi = env.arena
    lo = max(float(min(centre - side / 2)), a_lo - 0.5)
    hi = min(float(max(centre + side / 2)), a_hi + 0.5)
    lo, hi = min(lo, hi - 2.0), max(hi, lo + 2.0)
    if len(points) == 1:  # nothing evaluated: show the start of the channel
        lo, hi = -1.0, 9.0

    first_starts = [
        r.trajectories[0][0] for r in chosen.values() if r is not None and r.trajectories
    ]
    same = all(np.allclose(s, first_starts[0]) for s in first_starts)
    for ax in axes[len(configs) :]:
        ax.set_visible(False)
    for ax, config in zip(axes, configs, strict=False):
        run = chosen[config]
        color = _color(config, configs)
        cenv = run.env if run is not None else env
        _draw_channel(ax, cenv.half_width, lo - 5, hi + 5)
        ax.set_xlim(lo, hi)
        ax.set_ylim(lo, hi)
        ax.set_aspect("equal", adjustable="box")
        ax.grid(True, color="0.9", linewidth=0.5)
        ax.set_axisbelow(True)
        if run is None or run.trajectories is None:
            ax.set_title(_label(config), color=color, fontweight="bold", fontsize=10)
            _no_data(ax, "no evaluation")
            continue
        start, trial = run.trajectories[0][0], run.trajectories[1][0]
        for k, dims in enumerate(GOAL_DIMS):
            centre_k = start[list(dims)]
            ax.add_patch(
                Circle(
                    centre_k,
                    cenv.goal_radius,
                    facecolor=_GOAL_COLOR,
                    alpha=0.35,
                    edgecolor=_GOAL_COLOR,
                    lw=1.2,
                )
            )
            ax.text(*centre_k, f"g{k + 1}", ha="center", va="center", fontsize=9, weight="bold")
        moving = run.obstacle_paths[0] if run.obstacle_paths else None
        for k, dims in enumerate(OBSTACLE_DIMS):
            where = start[list(dims)] if moving is None else moving[-1, 2 * k : 2 * k + 2]
            if moving is not None:
                ax.plot(
                    moving[:, 2 * k], moving[:, 2 * k + 1], color=_OBSTACLE_COLOR, lw=1.0, ls=":"
                )
            ax.add_patch(
                Circle(
                    where,
                    cenv.obstacle_radius,
                    facecolor="none",
                    edgecolor=_OBSTACLE_COLOR,
                    hatch="////",
                    lw=1.0,
                )
            )
        ax.plot(trial[:, 0], trial[:, 1], color=color, lw=1.8)
        ax.plot(*trial[0], "o", ms=7, mfc="white", mec="black", mew=1.2, zorder=4)
        ax.plot(*trial[-1], "X", ms=9, mfc=color, mec="black", mew=0.8, zorder=4)
        ax.set_title(
            f"{_label(config)} (seed {run.seed}): {_trial_outcome(run, start, trial)}",
            color=color,
            fontweight="bold",
            fontsize=10,
        )
    for ax in axes[-ncols:]:
        ax.set_xlabel("x [m]")
    for ax in axes[::ncols]:
        ax.set_ylabel("y [m]")
    handles = [
        Patch(
            facecolor=_CHANNEL_COLOR,
            alpha=0.25,
            label=f"channel |x {_MINUS} y| < {env.half_width:g}",
        ),
        Patch(facecolor=_GOAL_COLOR, alpha=0.45, label="goals g1, g2, g3"),
        Patch(
            facecolor="none",
            edgecolor=_OBSTACLE_COLOR,
            hatch="////",
            label="obstacles at the end (dotted: their paths)",
        ),
        Line2D([], [], ls="none", marker="o", ms=7, mfc="white", mec="black", label="start"),
        Line2D([], [], ls="none", marker="X", ms=9, mfc="0.6", mec="black", label="end"),
    ]
    fig.legend(handles=handles, loc="outside lower center", ncols=5, fontsize=9)
    evaluations = [r.evaluation for r in chosen.values() if r is not None and r.evaluation]
    seeds = {e.get("eval_seed") for e in evaluations}
    trial_name = "evaluation trial 1"
    if len(seeds) == 1 and None not in seeds:
        trial_name += f" (reset seed {seeds.pop()})"
    note = "" if same else " — note: the panels' trials differ"
    fig.suptitle(f"Paths of {trial_name}, CBF on{note}")
    return _save(fig, path)


# --- the task automaton ----------------------------------------------------------------------


def _pretty_guard(guard: str) -> str:
    """A guard in logic symbols, one disjunct per line."""
    text = guard.replace("!", _NOT).replace(" & ", f" {_AND} ")
    return f"\n{_OR} ".join(text.split(" | "))


def _automaton_layout(automaton: Any) -> dict[int, tuple[float, float]]:
    """Positions: the longest-path depth from the initial state left to right (self loops and
    edges into the trap ignored), states of a depth stacked; the trap below, centred under its
    predecessors."""
    n, trap = automaton.num_states, automaton.trap
    edges = [(a, b) for a, b, _ in automaton.edges() if a != b and b != trap and a != trap]
    depth = dict.fromkeys(range(n), 0)
    for _ in range(n):  # Bellman-Ford style relaxation; bounded, so cycles cannot loop forever
        changed = False
        for a, b in edges:
            if b != automaton.initial and depth[b] < depth[a] + 1 and depth[a] + 1 < n:
                depth[b] = depth[a] + 1
                changed = True
        if not changed:
            break
    columns: dict[int, list[int]] = {}
    for q in range(n):
        if q != trap:
            columns.setdefault(depth[q], []).append(q)
    pos: dict[int, tuple[float, float]] = {}
    for d, states in columns.items():
        for i, q in enumerate(states):
            pos[q] = (4.0 * d, 2.8 * (i - (len(states) - 1) / 2))
    if trap is not None:
        sources = [pos[a] for a, b, _ in automaton.edges() if b == trap and a != trap]
        x = float(np.mean([p[0] for p in sources])) if sources else 0.0
        y = min((p[1] for p in pos.values()), default=0.0) - 3.6
        pos[trap] = (x, y)
    return pos


def _draw_automaton(automaton: Any, path: Path) -> Path:
    """The automaton drawn with matplotlib (when Graphviz is not installed)."""
    from matplotlib.patches import Circle, FancyArrowPatch

    pos = _automaton_layout(automaton)
    xs = [p[0] for p in pos.values()]
    ys = [p[1] for p in pos.values()]
    xlim = (min(xs) - 2.6, max(xs) + 1.4)
    ylim = (min(ys) - 1.9, max(ys) + 3.3)
    scale = 0.7  # inches per data unit (aspect 1)
    fig = _figure(scale * (xlim[1] - xlim[0]), scale * (ylim[1] - ylim[0]) + 0.4)
    ax = fig.subplots()
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal")
    ax.set_axis_off()
    radius = 0.55
    label_style: dict[str, Any] = {
        "ha": "center",
        "va": "center",
        "fontsize": 8,
        "bbox": {"boxstyle": "round,pad=0.25", "facecolor": "white", "edgecolor": "0.8", "lw": 0.5},
        "zorder": 5,
    }
    arrow_style: dict[str, Any] = {
        "arrowstyle": "-|>",
        "mutation_scale": 14,
        "lw": 1.1,
        "color": "black",
    }
    accepting, trap = set(automaton.accepting), automaton.trap
    for q, (x, y) in pos.items():
        fill = "#f4b6b6" if q == trap else "white"
        ax.add_patch(Circle((x, y), radius, facecolor=fill, edgecolor="black", lw=1.3, zorder=3))
        if q in accepting:
            ax.add_patch(
                Circle((x, y), radius * 0.82, facecolor="none", edgecolor="black", lw=1.0, zorder=4)
            )
        name = f"q{q}\ntrap" if q == trap else f"q{q}"
        ax.text(x, y, name, ha="center", va="center", fontsize=10, zorder=4)
    x0, y0 = pos[automaton.initial]
    ax.add_patch(FancyArrowPatch((x0 - 1.6, y0), (x0 - radius, y0), **arrow_style))
    ax.text(x0 - 1.7, y0, "start", ha="right", va="center", fontsize=9)
    depth_gap = 4.0
    for a, b, guard in automaton.edges():
        text = _pretty_guard(guard)
        pa, pb = np.array(pos[a]), np.array(pos[b])
        if a == b:
            # A loop above the state (below for the trap, which sits at the bottom).
            sign = -1.0 if b == trap else 1.0
            y = float(pa[1] + sign * 0.8 * radius)
            loop = FancyArrowPatch(
                (float(pa[0] - 0.6 * radius), y),
                (float(pa[0] + 0.6 * radius), y),
                connectionstyle=f"arc3,rad={-1.8 * sign}",
                zorder=2,
                **arrow_style,
            )
            ax.add_patch(loop)
            va = "bottom" if sign > 0 else "top"
            ax.text(pa[0], pa[1] + sign * 1.3, text, **{**label_style, "va": va})
            continue
        dx, dy = pb - pa
        skips = abs(dy) < 1e-9 and abs(dx) > depth_gap + 1e-9
        rad = -0.6 if skips else 0.0  # arc over the states in between
        # arc3's control point; the arrow leaves and enters the circles towards it.
        control = (pa + pb) / 2 + rad * np.array([dy, -dx])
        start = pa + radius * (control - pa) / np.linalg.norm(control - pa)
        end = pb + radius * (control - pb) / np.linalg.norm(control - pb)
        sx, sy = end - start
        arrow = FancyArrowPatch(
            (float(start[0]), float(start[1])),
            (float(end[0]), float(end[1])),
            connectionstyle=f"arc3,rad={rad}",
            zorder=2,
            **arrow_style,
        )
        ax.add_patch(arrow)
        # The midpoint of the quadratic Bezier of arc3 (data and display share the aspect).
        mid = (start + end) / 2 + 0.5 * rad * np.array([sy, -sx])
        ax.text(mid[0], mid[1], text, **label_style)
    ax.set_title("Task automaton (FSA of the scTLTL task)", fontsize=11)
    return _save(fig, path)


def _plot_automaton(path: Path) -> Path:
    """The task automaton: Graphviz if ``dot`` is installed, else matplotlib."""
    automaton = channel_task_spec().automaton()
    dot = shutil.which("dot")
    if dot is not None:
        try:
            subprocess.run(
                [dot, "-Tpng", f"-Gdpi={DPI}", "-Gbgcolor=white", "-o", str(path)],
                input=automaton.to_dot(),
                text=True,
                check=True,
                capture_output=True,
                timeout=60,
            )
            return path
        except (OSError, subprocess.SubprocessError) as err:
            warnings.warn(
                f"graphviz dot failed ({err}); drawing the automaton with matplotlib",
                RuntimeWarning,
                stacklevel=2,
            )
    return _draw_automaton(automaton, path)


def plot_all(results: str | Path, out: str | Path | None = None) -> list[Path]:
    """Writes the figures (:data:`FIGURES`) of a results folder into ``out`` (default
    ``results/figures``) and returns their paths. Missing pieces (runs without metrics,
    evaluation or trajectories) are left out of the figures, never an error."""
    groups = load_results(results)
    folder = Path(out) if out is not None else Path(results) / "figures"
    folder.mkdir(parents=True, exist_ok=True)
    return [
        _plot_learning_curves(groups, folder / FIGURES[0]),
        _plot_min_constraints(groups, folder / FIGURES[1]),
        _plot_min_obstacle_distance(groups, folder / FIGURES[2]),
        _plot_success_rates(groups, folder / FIGURES[3]),
        _plot_trajectories(groups, folder / FIGURES[4]),
        _plot_automaton(folder / FIGURES[5]),
    ]
