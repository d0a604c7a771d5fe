"""The time-to-solve figure of docs/learning.md: validation success against wall-clock seconds,
one thin line per seed and the mean bold, for several sets of runs on the same machine.

    .venv/bin/python scripts/time_to_solve.py OUT.png LABEL=FOLDER [LABEL=FOLDER ...]

Each FOLDER holds run folders (``<config>_s<seed>``, as ``tlshield reproduce`` and
scripts/learning_experiments.py write them); one panel per configuration. The mean is taken
over the seeds on a common time grid, each seed's curve held at its last validation after the
run ended.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from tlshield.lab.runs import load_results

COLORS = ("#7f7f7f", "#1f77b4", "#d62728", "#2ca02c", "#9467bd")


def main(out: str, sets: list[str]) -> None:
    from matplotlib.figure import Figure

    loaded = {}
    for item in sets:
        label, _, folder = item.partition("=")
        loaded[label] = load_results(Path(folder))
    configs = sorted({c for results in loaded.values() for c in results})
    fig = Figure(figsize=(6.5 * len(configs), 4.5), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(configs)))
    for ax, config in zip(axes, configs, strict=True):
        for (label, results), color in zip(loaded.items(), COLORS, strict=False):
            runs = results.get(config, [])
            curves = []
            for run in runs:
                t, v = run.metrics["wall_time"], run.metrics["validation_success"]
                ok = np.isfinite(v)
                if not ok.any():  # a run too short to validate
                    continue
                curves.append((t[ok], v[ok]))
                ax.plot(t[ok], v[ok], color=color, lw=0.7, alpha=0.5)
            if not curves:
                continue
            grid = np.linspace(0.0, max(c[0][-1] for c in curves), 200)
            held = [np.interp(grid, t, v, left=0.0, right=v[-1]) for t, v in curves]
            ax.plot(grid, np.mean(held, axis=0), color=color, lw=2.5, label=f"{label} (mean)")
        ax.set(
            title=config,
            xlabel="wall-clock seconds (one run per core)",
            ylabel="validation success (20 episodes)",
            ylim=(-0.02, 1.02),
        )
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right")
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        raise SystemExit(__doc__)
    main(sys.argv[1], sys.argv[2:])
