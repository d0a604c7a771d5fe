"""FlatWorld's map drawn with matplotlib: the coloured discs, the square, and agent paths on
top (the env's ``render``; the benchmark's figure, :mod:`tlshield.lab.plots.flatworld`, draws
the same map). Matplotlib is imported only when something is drawn."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

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
#: Dots per inch of the rendered map.
DPI = 150

#: Discs as ``(centre, radius, colour)``.
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
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4, 4), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    draw_map(ax, circles, size)
    for path in paths:
        ax.plot(path[:, 0], path[:, 1], color="k", lw=1.2)
        ax.plot(*path[0], "o", color="k", ms=4)
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
