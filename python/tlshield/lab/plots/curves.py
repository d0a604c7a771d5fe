"""Per-update curves (learning curves, channel barriers, obstacle distance: mean +- std over
seeds) and the evaluation success rates (Li & Belta, Figs. 6.2.1-6.2.4)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tlshield.lab.plots._style import _MINUS, _color, _env_of, _figure, _label, _no_data, _save
from tlshield.lab.report import seed_stat, trials_note
from tlshield.lab.runs import Run


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


def _training_of(groups: dict[str, list[Run]]) -> tuple[int, float]:
    """Environment steps per update and the discount of the runs (their run.json)."""
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


def _success_series(run: Run) -> tuple[NDArray[np.float64], NDArray[np.float64], bool]:
    """(updates, success, validated): the validation success where the run validated, else the
    fraction of the update's training episodes that succeeded, averaged over 10 updates."""
    x, val = run.metrics["update"], run.metrics["validation_success"]
    ok = np.isfinite(val)
    if ok.any():
        return x[ok], val[ok], True
    episodes = np.maximum(run.metrics["episodes"], 1.0)
    rate = run.metrics["successes"] / episodes
    window = min(10, len(rate)) or 1
    smooth = np.convolve(rate, np.ones(window) / window, mode="valid")
    return x[window - 1 :], smooth, False


def _plot_learning_curves(groups: dict[str, list[Run]], path: Path) -> Path:
    """Success per update (each seed thin, the mean over seeds bold): the validation success
    where the runs validated, else the training episodes' success rate; and the training
    violations per update: what learned, when, and whether it stayed learned."""
    configs = list(groups)
    fig = _figure(12.0, 5.2)
    success_ax, violation_ax = fig.subplots(1, 2)
    drawn, validated = False, True
    for config, runs in groups.items():
        color, label = _color(config, configs), _label(config)
        series = [_success_series(r) for r in runs if r.updates > 0]
        for x, y, was_validated in series:
            success_ax.plot(x, y, color=color, lw=0.8, alpha=0.45)
            validated &= was_validated
        if series:
            last = int(max(x.max() for x, _, _ in series))
            table = np.full((len(series), last), np.nan)
            for i, (x, y, _) in enumerate(series):
                table[i, x.astype(np.int64) - 1] = y
            mean, _ = _nan_mean_std(table)
            ok = np.isfinite(mean)
            steps = np.arange(1, last + 1)
            success_ax.plot(
                steps[ok], mean[ok], color=color, lw=2.0, label=f"{label} ({len(series)})"
            )
            drawn = True
        _plot_band(violation_ax, runs, "violations", color, label)
    if not drawn:
        _no_data(success_ax, "no training metrics yet")
    success_ax.set_ylim(-0.02, 1.02)
    success_ax.set_ylabel(
        "validation success (deterministic policy, 20 episodes)"
        if validated
        else "success of the training episodes (10-update mean)"
    )
    success_ax.set_title("Success per update: bold = mean, thin = each seed")
    violation_ax.set_ylim(bottom=0)
    violation_ax.set_ylabel("channel-violating steps in the update")
    violation_ax.set_title("Training violations per update (mean ± std over seeds)")
    steps_per_update = _training_of(groups)[0]
    for ax in (success_ax, violation_ax):
        _update_axis(ax, steps_per_update)
    if drawn:
        handles, labels = success_ax.get_legend_handles_labels()
        fig.legend(handles, labels, loc="outside lower center", ncols=min(len(labels), 4))
    fig.suptitle("Learning: success per update, and safety during training")
    return _save(fig, path)


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
    obstacles = _env_of(groups).obstacles
    radius, safe = obstacles.obstacle_radius, obstacles.safe_distance
    return _curves_figure(
        groups,
        [("min_obstacle_distance", "")],
        "smallest distance to an obstacle [m]",
        "Smallest obstacle distance per update (mean ± std over seeds)",
        path,
        hlines=[
            (radius, "-", f"collision distance ({radius:g} m)"),
            (safe, ":", f"reward safe distance ({safe:g} m)"),
        ],
        shade_below=radius,
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
        stat = seed_stat(rates)
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
        ticks.append(f"{_label(config)}\n{mean:.2f} ± {std:.2f}\n({trials_note(evaluations)})")
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
