"""A small matplotlib renderer for the channel case study (Li & Belta, Sec. VI).

:class:`ChannelRenderer` draws one frame of the scene -- the channel band ``|x - y| < w``
between the lines ``c1: x - y + w = 0`` and ``c2: y - x + w = 0``, the goals g1, g2, g3, the
obstacles o1, o2, the trajectory so far and the agent with its heading -- into an RGB array.
It backs ``ChannelEnv.render()``.

Rendering is headless: frames are drawn with the Agg backend on a private
:class:`matplotlib.figure.Figure` (never through :mod:`matplotlib.pyplot`), so no global state is
touched. The static part (axes, ticks, the channel) is drawn once and kept as a background
bitmap; each frame restores it and redraws only the moving artists (blitting), which takes a
few milliseconds. Only :meth:`ChannelRenderer.show` (``render_mode="human"``) uses pyplot.

matplotlib is imported lazily, so :mod:`tlshield` imports without it.
"""

from __future__ import annotations

import contextlib
import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tlshield.envs.layout import GOAL_DIMS, OBSTACLE_DIMS, STATE_DIM, THETA, X, Y

__all__ = ["ChannelRenderer", "Scene", "draw_channel"]


#: Length of the heading arrow (data units, metres).
_ARROW_LENGTH = 0.6
#: The figure is always this many inches square; the dpi is ``size / _INCHES``. A power of two
#: makes ``_INCHES * (size / _INCHES) == size`` exact, and sizes in points (fonts, line widths,
#: markers) scale with ``size``, so a frame looks the same at every resolution.
_INCHES = 4.0

#: The labels of the text box (equal lengths: the numbers follow them in one column), and the
#: room (characters) the box keeps for the numbers.
_INFO_LABELS = ("q    = ", "step = ")
_INFO_DIGITS = 5

_CHANNEL_COLOR = "#1f77b4"
_GOAL_COLORS = ("#2ca02c", "#ff7f0e", "#9467bd")  # g1 green, g2 orange, g3 purple
_OBSTACLE_COLOR = "#d62728"
_OBSTACLE_EDGE = "#7f1010"
_TRAJECTORY_COLOR = "#333333"
_AGENT_COLOR = "black"

#: Non-interactive matplotlib backends (lower case): ``show`` cannot open a window with these.
_NON_INTERACTIVE = frozenset(
    {"agg", "cairo", "pdf", "pgf", "ps", "svg", "template", "module://matplotlib_inline"}
)


def draw_channel(
    ax: Any,
    half_width: float,
    lo: float,
    hi: float,
    *,
    alpha: float,
    zorder: float = 1,
    label: str | None = None,
) -> None:
    """The channel ``|x - y| < half_width`` on ``ax`` from ``x = lo`` to ``x = hi``: the band
    between ``c2: y = x - w`` and ``c1: y = x + w`` and its two border lines (also used by the
    trajectory figure)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Polygon

    w = float(half_width)
    band = [(lo, lo - w), (hi, hi - w), (hi, hi + w), (lo, lo + w)]
    ax.add_patch(
        Polygon(
            band,
            closed=True,
            facecolor=_CHANNEL_COLOR,
            alpha=alpha,
            edgecolor="none",
            zorder=zorder,
            label=label,
        )
    )
    for offset in (w, -w):
        ax.add_line(Line2D([lo, hi], [lo + offset, hi + offset], color=_CHANNEL_COLOR, lw=0.9))


@dataclass(frozen=True)
class Scene:
    """The fixed geometry of the channel scene."""

    #: ``w`` of the channel constraints ``c1: x - y + w > 0`` and ``c2: y - x + w > 0``.
    half_width: float
    #: Radius of the goal discs g1, g2, g3.
    goal_radius: float
    #: Radius of the obstacle discs o1, o2 (the collision distance).
    obstacle_radius: float
    #: ``(xmin, xmax, ymin, ymax)``: the plot limits.
    arena: tuple[float, float, float, float]


class ChannelRenderer:
    """Draws frames of the channel scene into ``(size, size, 3)`` ``uint8`` arrays.

    The figure and every artist are built on the first :meth:`frame` (matplotlib is imported
    then); later frames only move artists. Output is deterministic: the same inputs give the
    same bytes.
    """

    def __init__(self, scene: Scene, size: int = 512) -> None:
        """Prepare a renderer for ``scene`` producing ``size`` x ``size`` pixel frames."""
        xmin, xmax, ymin, ymax = (float(v) for v in scene.arena)
        if not (xmin < xmax and ymin < ymax):
            raise ValueError(f"arena = {scene.arena!r}: expected xmin < xmax and ymin < ymax")
        if scene.half_width <= 0 or scene.goal_radius <= 0 or scene.obstacle_radius <= 0:
            raise ValueError(f"{scene!r}: half_width and the radii must be positive")
        if int(size) < 64:
            raise ValueError(f"size = {size!r}: expected at least 64 pixels")
        self.scene = scene
        self.size = int(size)
        # The figure and its artists, built by _build() on the first frame.
        self._fig: Any = None
        self._canvas: Any = None
        self._ax: Any = None
        self._background: Any = None
        self._info: Any = None
        self._values: Any = None
        self._traj: Any = None
        self._start: Any = None
        self._agent: Any = None
        self._arrow: Any = None
        self._goals: list[Any] = []
        self._goal_labels: list[Any] = []
        self._obstacles: list[Any] = []
        self._obstacle_labels: list[Any] = []
        self._moving: list[Any] = []
        self._window: Any = None  # (pyplot figure, AxesImage) of show()
        self._show_disabled = False
        self._title = ""

    # --- building ------------------------------------------------------------------------

    def _build(self, title: str) -> None:
        """Create the figure, the static artists, the moving artists (``animated=True``: a full
        draw leaves them out) and the background bitmap."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
        from matplotlib.lines import Line2D
        from matplotlib.patches import Circle, FancyArrowPatch
        from matplotlib.transforms import ScaledTranslation

        sc = self.scene
        xmin, xmax, ymin, ymax = (float(v) for v in sc.arena)
        w = float(sc.half_width)

        fig = Figure(figsize=(_INCHES, _INCHES), dpi=self.size / _INCHES, facecolor="white")
        canvas = FigureCanvasAgg(fig)
        ax = fig.add_axes((0.1, 0.08, 0.87, 0.87))
        ax.set_xlim(xmin, xmax)
        ax.set_ylim(ymin, ymax)
        ax.set_aspect("equal", adjustable="box")
        ax.set_autoscale_on(False)
        ax.tick_params(labelsize=6, length=2, pad=1.5)
        ax.set_xlabel("x [m]", fontsize=6, labelpad=1)
        ax.set_ylabel("y [m]", fontsize=6, labelpad=1)
        ax.grid(True, color="0.9", linewidth=0.4, zorder=0)
        ax.set_axisbelow(True)

        # The channel, long enough to cover the arena; the axes clip it.
        lo = min(xmin, ymin) - w - 1.0
        hi = max(xmax, ymax) + w + 1.0
        draw_channel(ax, w, lo, hi, alpha=0.12, zorder=1)
        for name, offset in (("c1", w), ("c2", -w)):
            self._label_line(ax, name, offset)

        # Moving artists. Labels are mathtext markers: drawn as cached paths, several times
        # cheaper than Text artists.
        traj = Line2D([], [], color=_TRAJECTORY_COLOR, lw=0.9, alpha=0.85, animated=True)
        start = Line2D(
            [],
            [],
            ls="none",
            marker="o",
            ms=2.5,
            mfc="white",
            mec=_TRAJECTORY_COLOR,
            mew=0.7,
            animated=True,
        )
        goals, goal_labels = [], []
        for k, color in enumerate(_GOAL_COLORS):
            goals.append(
                Circle(
                    (0.0, 0.0),
                    sc.goal_radius,
                    facecolor=color,
                    alpha=0.55,
                    edgecolor=color,
                    lw=1.0,
                    animated=True,
                )
            )
            goal_labels.append(self._marker_label(ax, f"g{k + 1}", color, 9.0))
        obstacles, obstacle_labels = [], []
        for k in range(len(OBSTACLE_DIMS)):
            obstacles.append(
                Circle(
                    (0.0, 0.0),
                    sc.obstacle_radius,
                    facecolor=_OBSTACLE_COLOR,
                    edgecolor=_OBSTACLE_EDGE,
                    lw=0.8,
                    animated=True,
                )
            )
            obstacle_labels.append(self._marker_label(ax, f"o{k + 1}", _OBSTACLE_EDGE, 7.5))
        for patch in (*goals, *obstacles):
            ax.add_patch(patch)
        ax.add_line(traj)
        ax.add_line(start)
        arrow = FancyArrowPatch(
            (0.0, 0.0),
            (1.0, 0.0),
            arrowstyle="-|>",
            mutation_scale=7,
            lw=1.2,
            color=_AGENT_COLOR,
            shrinkA=0.0,
            shrinkB=0.0,
            animated=True,
        )
        ax.add_patch(arrow)
        agent = Line2D(
            [],
            [],
            ls="none",
            marker="o",
            ms=5,
            mfc=_AGENT_COLOR,
            mec="white",
            mew=0.7,
            animated=True,
        )
        ax.add_line(agent)

        # The text box: the box, its labels and the title are static (drawn into the
        # background, again when the title changes: _set_title); only the numbers move, as a
        # second text shifted right by the width of the labels. Text widths are advance
        # based, and the font is monospace, so the numbers line up with the labels.
        style: dict[str, Any] = {
            "fontsize": 6.5,
            "family": "monospace",
            "ha": "left",
            "va": "top",
            "transform": ax.transAxes,
        }
        info = ax.text(
            0.025,
            0.975,
            "",
            zorder=9,
            **style,
            bbox={
                "boxstyle": "round,pad=0.35",
                "facecolor": "white",
                "edgecolor": "0.6",
                "alpha": 0.9,
                "lw": 0.6,
            },
        )
        label_width, _, _ = canvas.get_renderer().get_text_width_height_descent(
            _INFO_LABELS[0], info.get_fontproperties(), ismath=False
        )
        style["transform"] = ax.transAxes + ScaledTranslation(
            label_width / fig.dpi, 0.0, fig.dpi_scale_trans
        )
        values = ax.text(0.025, 0.975, "", zorder=10, animated=True, **style)

        self._fig, self._canvas, self._ax = fig, canvas, ax
        self._traj, self._start, self._agent, self._arrow = traj, start, agent, arrow
        self._info, self._values = info, values
        self._goals, self._goal_labels = goals, goal_labels
        self._obstacles, self._obstacle_labels = obstacles, obstacle_labels
        # The moving artists in drawing order (draw_artist ignores zorder).
        self._moving = [
            *goals,
            *obstacles,
            traj,
            start,
            *goal_labels,
            *obstacle_labels,
            arrow,
            agent,
            values,
        ]
        self._set_title(title)

    def _set_title(self, title: str) -> None:
        """Write the static part of the text box with ``title``, and redraw the background
        (the static scene: a full draw leaves the animated artists out)."""
        lines = [label + " " * _INFO_DIGITS for label in _INFO_LABELS]
        if title:
            lines.append(title)
        self._info.set_text("\n".join(lines))
        self._canvas.draw()
        self._background = self._canvas.copy_from_bbox(self._fig.bbox)
        self._title = title

    @staticmethod
    def _marker_label(ax: Any, name: str, color: str, size: float) -> Any:
        """A one-point Line2D whose marker is ``name`` in bold mathtext, ``size`` points wide,
        drawn with its lower-left corner about at the data point."""
        from matplotlib.lines import Line2D
        from matplotlib.transforms import ScaledTranslation

        half = size / 2.0 / 72.0  # inches
        offset = ScaledTranslation(half, 0.6 * half, ax.get_figure().dpi_scale_trans)
        label = Line2D(
            [],
            [],
            ls="none",
            marker=f"$\\mathbf{{{name}}}$",
            ms=size,
            mfc=color,
            mec="none",
            animated=True,
            transform=ax.transData + offset,
        )
        ax.add_line(label)
        return label

    def _label_line(self, ax: Any, name: str, offset: float) -> None:
        """Write ``name`` along the line ``y = x + offset``, outside the band, near the start of
        its visible part; nothing if the line misses the arena."""
        xmin, xmax, ymin, ymax = (float(v) for v in self.scene.arena)
        a, b = max(xmin, ymin - offset), min(xmax, ymax - offset)  # visible x range
        if a >= b:
            return
        x = a + 0.06 * (b - a)
        shift = 0.04 * min(xmax - xmin, ymax - ymin)  # across the line, away from the band
        side = 1.0 if offset > 0 else -1.0
        ax.text(
            x - side * shift,
            x + offset + side * shift,
            name,
            fontsize=6.5,
            color=_CHANNEL_COLOR,
            rotation=45,
            rotation_mode="anchor",
            ha="left",
            va="center",
            zorder=2,
            clip_on=True,
        )

    # --- drawing -------------------------------------------------------------------------

    def frame(
        self,
        state: NDArray[np.floating] | Any,
        trajectory: NDArray[np.floating] | Any,
        fsa_state: int,
        step: int,
        title: str = "",
    ) -> NDArray[np.uint8]:
        """Render one frame.

        Args:
            state: the 13-value state (``x, y, theta``, goal centres g1..g3, obstacle centres
                o1, o2).
            trajectory: the reference point's positions so far, shape ``(k, 2)`` (``k`` may be
                0 or 1; an empty array of any shape counts as ``k = 0``).
            fsa_state: the FSA state ``q`` shown in the text box.
            step: the step number shown in the text box.
            title: a further line of the text box (e.g. the configuration); omitted if empty.

        Returns:
            An RGB ``uint8`` array of shape ``(size, size, 3)``.
        """
        s = np.asarray(state, dtype=np.float64).ravel()
        if s.size < STATE_DIM:
            raise ValueError(f"state has {s.size} values, expected {STATE_DIM}")
        traj = np.asarray(trajectory, dtype=np.float64)
        if traj.size == 0:
            traj = np.empty((0, 2))
        if traj.ndim != 2 or traj.shape[1] != 2:
            raise ValueError(f"trajectory has shape {traj.shape}, expected (k, 2)")
        title = str(title)
        if self._fig is None:
            self._build(title)
        elif title != self._title:
            self._set_title(title)

        x, y, theta = s[X], s[Y], s[THETA]
        for circle, label, (i, j) in zip(self._goals, self._goal_labels, GOAL_DIMS, strict=True):
            self._place(circle, label, s[i], s[j], self.scene.goal_radius)
        for circle, label, (i, j) in zip(
            self._obstacles, self._obstacle_labels, OBSTACLE_DIMS, strict=True
        ):
            self._place(circle, label, s[i], s[j], self.scene.obstacle_radius)
        self._traj.set_data(traj[:, 0], traj[:, 1])
        self._start.set_data(traj[:1, 0], traj[:1, 1])
        self._agent.set_data([x], [y])
        tip = (x + _ARROW_LENGTH * math.cos(theta), y + _ARROW_LENGTH * math.sin(theta))
        self._arrow.set_positions((x, y), tip)
        self._values.set_text(f"{int(fsa_state)}\n{int(step)}")

        canvas = self._canvas
        canvas.restore_region(self._background)
        for artist in self._moving:
            self._ax.draw_artist(artist)
        return self._rgb()

    def _rgb(self) -> NDArray[np.uint8]:
        """The canvas as a fresh RGB array (via Pillow, a matplotlib dependency: its C
        conversion is about twice as fast as a strided numpy copy)."""
        from PIL import Image

        width, height = (int(v) for v in self._canvas.get_width_height(physical=True))
        if (width, height) != (self.size, self.size):  # pragma: no cover - see _INCHES
            raise RuntimeError(f"canvas is {width}x{height}, expected {self.size} square")
        buf = self._canvas.buffer_rgba()
        image = Image.frombuffer("RGBA", (width, height), buf, "raw", "RGBA", 0, 1)
        return np.array(image.convert("RGB"))

    @staticmethod
    def _place(circle: Any, label: Any, cx: float, cy: float, radius: float) -> None:
        """Move a disc and its label (just above-right of the disc) to ``(cx, cy)``."""
        circle.set_center((cx, cy))
        d = 0.7 * radius
        label.set_data([cx + d], [cy + d])

    # --- display -------------------------------------------------------------------------

    def show(self, image: NDArray[np.uint8]) -> None:
        """Show ``image`` in a window (``render_mode="human"``), without blocking.

        Uses pyplot in interactive mode. Without a display (a non-interactive backend, or any
        error opening the window) it does nothing, after one warning per renderer.
        """
        if self._show_disabled:
            return
        try:
            import matplotlib.pyplot as plt

            backend = str(plt.get_backend()).lower()
            if backend in _NON_INTERACTIVE:
                self._disable_show(f"matplotlib backend {backend!r} cannot open a window")
                return
            plt.ion()
            if self._window is None or not plt.fignum_exists(self._window[0].number):
                fig = plt.figure("tlshield channel", figsize=(6.0, 6.0))
                fig.clear()
                ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
                ax.set_axis_off()
                self._window = (fig, ax.imshow(image, interpolation="nearest"))
                plt.show(block=False)
            else:
                self._window[1].set_data(image)
                self._window[0].canvas.draw_idle()
            plt.pause(0.001)
        except Exception as exc:  # no display, closed window, backend errors ...
            self._disable_show(f"{type(exc).__name__}: {exc}")

    def _disable_show(self, reason: str) -> None:
        """Turn :meth:`show` into a no-op, with one warning."""
        self._show_disabled = True
        warnings.warn(
            f"ChannelRenderer.show: cannot display frames ({reason}); not showing them",
            RuntimeWarning,
            stacklevel=3,
        )

    def close(self) -> None:
        """Release the figure and close the window of :meth:`show`, if any. A later
        :meth:`frame` builds a new figure."""
        if self._window is not None:
            with contextlib.suppress(Exception):  # closing the window is best effort
                import matplotlib.pyplot as plt

                plt.close(self._window[0])
            self._window = None
        self._fig = self._canvas = self._ax = self._background = None
        self._info = self._values = self._traj = self._start = self._agent = self._arrow = None
        self._goals, self._goal_labels, self._obstacles, self._obstacle_labels = [], [], [], []
        self._moving = []
