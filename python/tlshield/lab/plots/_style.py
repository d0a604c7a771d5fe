"""What every figure shares: the configurations' colours and labels, the Agg figure and its
saving. matplotlib is imported lazily and only through the Agg canvas (never
:mod:`matplotlib.pyplot`), so plotting touches no global state and needs no display."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tlshield.envs.channel import ChannelParams
from tlshield.lab.runs import Run

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


DPI = 150


#: Typographic symbols of figure labels (escaped: they look like ASCII letters in source).
_MINUS, _AND, _OR, _NOT = "\u2212", "\u2227", "\u2228", "\u00ac"


def _color(config: str, configs: Sequence[str]) -> str:
    if config in CONFIG_COLORS:
        return CONFIG_COLORS[config]
    others = [c for c in configs if c not in CONFIG_COLORS]
    return _EXTRA_COLORS[others.index(config) % len(_EXTRA_COLORS)]


def _label(config: str) -> str:
    return CONFIG_LABELS.get(config, config)


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


def _env_of(groups: dict[str, list[Run]]) -> ChannelParams:
    return next(iter(groups.values()))[0].env
