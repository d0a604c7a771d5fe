"""FlatWorld's map: the coloured discs, the square, and agent paths on top (the env's render
and the benchmark's figure)."""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tlshield.plots._style import _figure, _save

#: Matplotlib colours of the FlatWorld colours (aqua as cyan).
PALETTE = {
    "red": "#e41a1c",
    "magenta": "#e7298a",
    "yellow": "#ffd92f",
    "orange": "#ff7f00",
    "blue": "#377eb8",
    "green": "#4daf4a",
    "aqua": "#00e5ee",
}


Circles = Sequence[tuple[tuple[float, float], float, str]]


def draw_map(ax: Any, circles: Circles, size: float = 2.0) -> None:
    """The discs ``(centre, radius, colour)`` (translucent, so overlaps show) and the square
    ``[-size, size]^2`` on ``ax``."""
    from matplotlib.patches import Circle, Rectangle

    for centre, radius, colour in circles:
        ax.add_patch(Circle(centre, radius, color=PALETTE[colour], alpha=0.45, lw=0))
    ax.add_patch(Rectangle((-size, -size), 2 * size, 2 * size, fill=False, lw=1.2, color="0.2"))
    ax.set_xlim(-size - 0.05, size + 0.05)
    ax.set_ylim(-size - 0.05, size + 0.05)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])


def draw_paths(
    paths: Sequence[NDArray[np.float64]], circles: Circles, size: float = 2.0
) -> NDArray[np.uint8]:
    """The map with ``paths`` (each ``(T, 2)``) as an RGB array (the env's ``render``)."""
    fig = _figure(4, 4)
    ax = fig.add_subplot()
    draw_map(ax, circles, size)
    for path in paths:
        ax.plot(path[:, 0], path[:, 1], color="k", lw=1.2)
        ax.plot(*path[0], "o", color="k", ms=4)
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()


def plot_paths(
    panels: Sequence[tuple[str, Sequence[NDArray[np.float64]], Sequence[bool]]],
    path: Path,
    circles: Circles,
    size: float = 2.0,
) -> Path:
    """One panel per ``(title, paths, successes)``: successful paths in black, failed in red,
    starts as dots. Saved as a PNG at ``path``."""
    cols = min(len(panels), 5)
    rows = -(-len(panels) // cols)
    fig = _figure(3.0 * cols, 3.2 * rows)
    for k, (title, paths, successes) in enumerate(panels):
        ax = fig.add_subplot(rows, cols, k + 1)
        draw_map(ax, circles, size)
        for p, ok in zip(paths, successes, strict=True):
            colour = "k" if ok else "#d62728"
            ax.plot(p[:, 0], p[:, 1], color=colour, lw=0.9, alpha=0.85)
            ax.plot(*p[0], "o", color=colour, ms=3)
        # Long formulas wrap inside their panel instead of running into the next one.
        lines = [textwrap.fill(line, 46) for line in title.split("\n")]
        ax.set_title("\n".join(lines), fontsize=7)
    return _save(fig, path)
