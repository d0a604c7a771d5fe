"""Figures of a results folder (``tlshield reproduce`` / ``tlshield plot``; the folder's
schema is in :mod:`tlshield.lab.runs`, the results table in :mod:`tlshield.lab.report`).

:func:`plot_all` writes the figures of the paper's case study (Li & Belta, Figs. 6.2.1-6.2.5)
as 150 dpi PNGs:

* ``learning_curves.png``: validation success per PPO update (each seed and the mean) and the
  training violations per update;
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

from pathlib import Path

from tlshield.lab.plots._style import CONFIG_COLORS, CONFIG_LABELS
from tlshield.lab.plots.automaton import _plot_automaton
from tlshield.lab.plots.curves import (
    _plot_learning_curves,
    _plot_min_constraints,
    _plot_min_obstacle_distance,
    _plot_success_rates,
)
from tlshield.lab.plots.trajectories import _plot_trajectories
from tlshield.lab.runs import load_results

__all__ = ["CONFIG_COLORS", "CONFIG_LABELS", "FIGURES", "plot_all"]

#: File names written by :func:`plot_all`, in order.
FIGURES = (
    "learning_curves.png",
    "min_constraints.png",
    "min_obstacle_distance.png",
    "success_rates.png",
    "trajectories.png",
    "task_automaton.png",
)


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
