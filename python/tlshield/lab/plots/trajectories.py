"""The sample-trajectory figure (Li & Belta, Fig. 6.2.5): one common evaluation trial per
configuration, with the goals, the obstacles' paths and how the trial ended, as the evaluation
recorded it."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from tlshield.envs.layout import GOAL_DIMS, OBSTACLE_DIMS
from tlshield.envs.render import draw_channel
from tlshield.lab.plots._style import _MINUS, _color, _env_of, _figure, _label, _no_data, _save
from tlshield.lab.runs import Run

#: The scene's goal and obstacle styles (not colours of a configuration).
_GOAL_COLOR = "#9467bd"
_OBSTACLE_COLOR = "0.35"
_CHANNEL_COLOR = "#1f77b4"


def _trial_outcome(run: Run) -> str:
    """How trial 1 ended, as the evaluation recorded it (success, collision or time-out)."""
    outcomes = (run.evaluation or {}).get("outcomes")
    if not outcomes:
        return "outcome not recorded"
    first = outcomes[0]
    steps = first.get("steps")
    if first.get("success"):
        return f"success in {steps} steps"
    if first.get("collision"):
        return f"collision at step {steps}"
    return f"time-out ({steps} steps)"


def _trajectory_run(runs: Sequence[Run]) -> Run | None:
    """Seed 0's run, else the lowest seed's, among the runs with trajectories."""
    evaluated = [r for r in runs if r.trajectories is not None and len(r.trajectories[1])]
    if not evaluated:
        return None
    return next((r for r in evaluated if r.seed == 0), evaluated[0])


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
        points += [trial, goals - env.task.goal_radius, goals + env.task.goal_radius]
    cloud = np.vstack(points)
    lo_xy, hi_xy = cloud.min(axis=0) - 0.8, cloud.max(axis=0) + 0.8
    side = float(max(hi_xy - lo_xy))
    centre = (lo_xy + hi_xy) / 2
    a_lo, a_hi = env.agent.arena
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
        draw_channel(ax, cenv.task.half_width, lo - 5, hi + 5, alpha=0.1, label="channel")
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
                    cenv.task.goal_radius,
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
                    cenv.obstacles.obstacle_radius,
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
            f"{_label(config)} (seed {run.seed}): {_trial_outcome(run)}",
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
            label=f"channel |x {_MINUS} y| < {env.task.half_width:g}",
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
