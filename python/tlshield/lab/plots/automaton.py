"""The task automaton figure: Graphviz ``dot`` when installed, else drawn with matplotlib."""

from __future__ import annotations

import shutil
import subprocess
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from tlshield.envs.channel import channel_task_spec
from tlshield.lab.plots._style import _AND, _NOT, _OR, DPI, _figure, _save


def _pretty_guard(guard: str) -> str:
    """A guard in logic symbols, one disjunct per line."""
    text = guard.replace("!", _NOT).replace(" & ", f" {_AND} ")
    return f"\n{_OR} ".join(text.split(" | "))


def _automaton_layout(automaton: Any) -> dict[int, tuple[float, float]]:
    """Positions: the longest-path depth from the initial state left to right (self loops and
    edges into the trap ignored), states of a depth stacked; the trap below, centred under its
    predecessors."""
    n, trap = automaton.num_states, automaton.trap
    edges = [(a, b) for a, b, _ in automaton.edges() if a != b and b != trap and a != trap]
    depth = dict.fromkeys(range(n), 0)
    for _ in range(n):  # Bellman-Ford style relaxation; bounded, so cycles cannot loop forever
        changed = False
        for a, b in edges:
            if b != automaton.initial and depth[b] < depth[a] + 1 and depth[a] + 1 < n:
                depth[b] = depth[a] + 1
                changed = True
        if not changed:
            break
    columns: dict[int, list[int]] = {}
    for q in range(n):
        if q != trap:
            columns.setdefault(depth[q], []).append(q)
    pos: dict[int, tuple[float, float]] = {}
    for d, states in columns.items():
        for i, q in enumerate(states):
            pos[q] = (4.0 * d, 2.8 * (i - (len(states) - 1) / 2))
    if trap is not None:
        sources = [pos[a] for a, b, _ in automaton.edges() if b == trap and a != trap]
        x = float(np.mean([p[0] for p in sources])) if sources else 0.0
        y = min((p[1] for p in pos.values()), default=0.0) - 3.6
        pos[trap] = (x, y)
    return pos


def _draw_automaton(automaton: Any, path: Path) -> Path:
    """The automaton drawn with matplotlib (when Graphviz is not installed)."""
    from matplotlib.patches import Circle, FancyArrowPatch

    pos = _automaton_layout(automaton)
    xs = [p[0] for p in pos.values()]
    ys = [p[1] for p in pos.values()]
    xlim = (min(xs) - 2.6, max(xs) + 1.4)
    ylim = (min(ys) - 1.9, max(ys) + 3.3)
    scale = 0.7  # inches per data unit (aspect 1)
    fig = _figure(scale * (xlim[1] - xlim[0]), scale * (ylim[1] - ylim[0]) + 0.4)
    ax = fig.subplots()
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal")
    ax.set_axis_off()
    radius = 0.55
    label_style: dict[str, Any] = {
        "ha": "center",
        "va": "center",
        "fontsize": 8,
        "bbox": {"boxstyle": "round,pad=0.25", "facecolor": "white", "edgecolor": "0.8", "lw": 0.5},
        "zorder": 5,
    }
    arrow_style: dict[str, Any] = {
        "arrowstyle": "-|>",
        "mutation_scale": 14,
        "lw": 1.1,
        "color": "black",
    }
    accepting, trap = set(automaton.accepting), automaton.trap
    for q, (x, y) in pos.items():
        fill = "#f4b6b6" if q == trap else "white"
        ax.add_patch(Circle((x, y), radius, facecolor=fill, edgecolor="black", lw=1.3, zorder=3))
        if q in accepting:
            ax.add_patch(
                Circle((x, y), radius * 0.82, facecolor="none", edgecolor="black", lw=1.0, zorder=4)
            )
        name = f"q{q}\ntrap" if q == trap else f"q{q}"
        ax.text(x, y, name, ha="center", va="center", fontsize=10, zorder=4)
    x0, y0 = pos[automaton.initial]
    ax.add_patch(FancyArrowPatch((x0 - 1.6, y0), (x0 - radius, y0), **arrow_style))
    ax.text(x0 - 1.7, y0, "start", ha="right", va="center", fontsize=9)
    depth_gap = 4.0
    for a, b, guard in automaton.edges():
        text = _pretty_guard(guard)
        pa, pb = np.array(pos[a]), np.array(pos[b])
        if a == b:
            # A loop above the state (below for the trap, which sits at the bottom).
            sign = -1.0 if b == trap else 1.0
            y = float(pa[1] + sign * 0.8 * radius)
            loop = FancyArrowPatch(
                (float(pa[0] - 0.6 * radius), y),
                (float(pa[0] + 0.6 * radius), y),
                connectionstyle=f"arc3,rad={-1.8 * sign}",
                zorder=2,
                **arrow_style,
            )
            ax.add_patch(loop)
            va = "bottom" if sign > 0 else "top"
            ax.text(pa[0], pa[1] + sign * 1.3, text, **{**label_style, "va": va})
            continue
        dx, dy = pb - pa
        skips = abs(dy) < 1e-9 and abs(dx) > depth_gap + 1e-9
        rad = -0.6 if skips else 0.0  # arc over the states in between
        # arc3's control point; the arrow leaves and enters the circles towards it.
        control = (pa + pb) / 2 + rad * np.array([dy, -dx])
        start = pa + radius * (control - pa) / np.linalg.norm(control - pa)
        end = pb + radius * (control - pb) / np.linalg.norm(control - pb)
        sx, sy = end - start
        arrow = FancyArrowPatch(
            (float(start[0]), float(start[1])),
            (float(end[0]), float(end[1])),
            connectionstyle=f"arc3,rad={rad}",
            zorder=2,
            **arrow_style,
        )
        ax.add_patch(arrow)
        # The midpoint of the quadratic Bezier of arc3 (data and display share the aspect).
        mid = (start + end) / 2 + 0.5 * rad * np.array([sy, -sx])
        ax.text(mid[0], mid[1], text, **label_style)
    ax.set_title("Task automaton (FSA of the scTLTL task)", fontsize=11)
    return _save(fig, path)


def _plot_automaton(path: Path) -> Path:
    """The task automaton: Graphviz if ``dot`` is installed, else matplotlib."""
    automaton = channel_task_spec().automaton()
    dot = shutil.which("dot")
    if dot is not None:
        try:
            subprocess.run(
                [dot, "-Tpng", f"-Gdpi={DPI}", "-Gbgcolor=white", "-o", str(path)],
                input=automaton.to_dot(),
                text=True,
                check=True,
                capture_output=True,
                timeout=60,
            )
            return path
        except (OSError, subprocess.SubprocessError) as err:
            warnings.warn(
                f"graphviz dot failed ({err}); drawing the automaton with matplotlib",
                RuntimeWarning,
                stacklevel=2,
            )
    return _draw_automaton(automaton, path)
