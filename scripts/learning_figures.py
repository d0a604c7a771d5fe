"""The collapse figure of docs/learning.md: a collapsing and a healthy run side by side, from
their metrics.csv diagnostics, and both runs' evaluation paths with their kept (best validated)
and their last policy.

    .venv/bin/python scripts/learning_figures.py COLLAPSING_RUN HEALTHY_RUN OUT.png
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from tlshield.lab.runs import load_run


def _paths(run: Path, name: str) -> list[np.ndarray]:
    with np.load(run / name) as data:
        lengths, flat = data["lengths"], data["paths"]
    return list(np.split(flat, np.cumsum(lengths)[:-1]))


def main(collapsing: str, healthy: str, out: str) -> None:
    from matplotlib.figure import Figure

    runs = {"collapsing": load_run(collapsing), "healthy": load_run(healthy)}
    fig = Figure(figsize=(20, 8.5), layout="constrained")
    axes = fig.subplots(2, 4)
    curves = [
        ("validation_success", "validation success (20 episodes)", False),
        ("out_of_box", "sampled actions outside the box", False),
        ("value_loss", "value loss (log)", True),
        ("approx_kl", "approx. KL of the update (log)", True),
    ]
    for ax, (column, title, log) in zip(axes.flat[:4], curves, strict=True):
        for (label, run), color in zip(runs.items(), ("#d62728", "#2ca02c"), strict=True):
            assert run is not None
            x, y = run.metrics["update"], run.metrics[column]
            ok = np.isfinite(y) & ((y > 0) if log else True)
            ppo = run.record["ppo"]
            kind = f"{ppo.get('policy', 'gaussian')}, lr {ppo.get('learning_rate')}"
            kind += ", raw rewards" if ppo.get("norm_reward") is False else ", normalised rewards"
            ax.plot(x[ok], y[ok], color=color, label=f"{label}: {kind}, seed {run.seed}")
        ax.set_title(title)
        ax.set_xlabel("PPO update")
        if log:
            ax.set_yscale("log")
        ax.grid(True, color="0.9")
    axes.flat[0].legend(fontsize=8)
    panels = []
    for label in ("collapsing", "healthy"):
        run = runs[label]
        assert run is not None
        kept = run.record.get("kept", {}).get("update", "last")
        panels += [
            (run, "trajectories.npz", f"{label}, kept (update {kept})"),
            (run, "last_trajectories.npz", f"{label}, last (update 300)"),
        ]
    for ax, (run, name, title) in zip(axes.flat[4:], panels, strict=True):
        for path in _paths(run.path, name)[:20]:
            ax.plot(path[:, 0], path[:, 1], lw=0.8, alpha=0.7)
        xs = np.array([-2.0, 11.0])
        half = run.record.get("env", {}).get("half_width", 1.5)
        ax.plot(xs, xs + half, "k-", lw=0.6)
        ax.plot(xs, xs - half, "k-", lw=0.6)
        ax.set_xlim(-2, 11)
        ax.set_ylim(-2, 11)
        ax.set_aspect("equal")
        ax.set_title(f"{title}: 20 evaluation paths", fontsize=10)
    fig.suptitle("Why PPO unlearned the task (Channel-v0, rl_cbf_clf)")
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


if __name__ == "__main__":
    main(*sys.argv[1:4])
