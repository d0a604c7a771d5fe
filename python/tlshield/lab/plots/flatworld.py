"""The FlatWorld benchmark's figure: agent paths on FlatWorld's map
(:mod:`tlshield.envs.flatworld_map`, which the env's render draws too)."""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from tlshield.envs.flatworld_map import Circles, draw_map
from tlshield.lab.plots._style import _figure, _save


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
