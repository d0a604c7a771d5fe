"""``trials.png`` of ``tlshield tune``: each sample's objective against each searched setting."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tlshield.lab.plots._style import _figure, _save


def plot_trials(
    rows: list[dict[str, Any]],
    names: Sequence[str],
    kinds: dict[str, tuple[Any, ...]],
    path: Path,
) -> Path:
    """One panel per setting: the objective of every sample trained to the end (filled; -1 =
    violated the channel) and the last validation success of the samples ASHA stopped early
    (hollow), against the setting's value; the best sample is starred."""
    cols = min(4, max(1, len(names)))
    nrows = math.ceil(len(names) / cols)
    fig = _figure(3.2 * cols, 2.6 * nrows)
    axes = fig.subplots(nrows, cols, squeeze=False).ravel()
    done = [r for r in rows if r.get("objective") is not None]
    stopped = [
        r for r in rows if r.get("objective") is None and r.get("validation_success") is not None
    ]
    best = max(done, key=lambda r: r["objective"], default=None)
    for ax, name in zip(axes, names, strict=False):
        kind = kinds[name]
        options = list(kind[1]) if kind[0] == "choice" else None

        def x(row: dict[str, Any], name: str = name, options: list | None = options) -> Any:
            value = row["_params"].get(name)
            return options.index(value) if options is not None and value in options else value

        for group, style in (
            (done, {"color": "C0"}),
            (stopped, {"facecolors": "none", "edgecolors": "C7"}),
        ):
            points = [
                (x(r), r["objective"] if r in done else r["validation_success"])
                for r in group
                if x(r) is not None
            ]
            if points:
                xs, ys = zip(*points, strict=True)
                ax.scatter(xs, ys, s=18, **style)
        if best is not None and x(best) is not None:
            ax.scatter([x(best)], [best["objective"]], marker="*", s=140, color="C3", zorder=3)
        if options is not None:
            ax.set_xticks(range(len(options)), [str(o) for o in options])
            ax.set_xlim(-0.5, len(options) - 0.5)
        elif kind[0] == "float" and kind[3]:
            from matplotlib.ticker import NullFormatter

            ax.set_xscale("log")
            ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel(name)
        ax.set_ylim(-1.1, 1.05)
        ax.grid(alpha=0.3)
    for ax in axes[len(names) :]:
        ax.set_visible(False)
    axes[0].set_ylabel("objective (success, -1 = violation)")
    fig.suptitle(
        f"{len(rows)} samples: trained to the end (filled), stopped early by ASHA (hollow, last "
        "validation success); best starred",
        fontsize=9,
    )
    return _save(fig, path)
