"""What Safety-Gymnasium's pseudo-lidar says about the objects around the robot, and no more.

The reading (``safety_gymnasium/bases/base_task.py``, ``_obs_lidar_pseudo``; its
``LidarConf`` defaults are what the Goal tasks use: 16 bins, ``max_dist`` 3 m, alias on). For
each object, with ``v`` its centre in the agent body's frame (planar), ``d = |v|`` and
``ang = atan2(v_y, v_x) mod 2 pi``:

- bin ``b = floor(ang / B)``, ``B = 2 pi / bins`` (bin 0 *starts* at the body's +x axis, and
  the bins run counter-clockwise);
- ``s = max(0, max_dist - d) / max_dist``, and ``obs[b] = max(obs[b], s)``;
- with alias, ``a = ang / B - b``: ``obs[b + 1] = max(obs[b + 1], a s)`` and
  ``obs[b - 1] = max(obs[b - 1], (1 - a) s)`` (indices modulo ``bins``).

So each bin is a maximum: no object whose centre lies in bin ``b`` is nearer than
``floor_b = max_dist (1 - obs[b])`` (:func:`floors`), whatever else the bins hold, and a bin
that reads 0 has no centre nearer than ``max_dist``. A single object alone in its bin and both
neighbours is read exactly (:func:`nearest`): ``d = max_dist (1 - s)`` and
``ang = (b + obs[b + 1] / s) B``. Where objects share bins, farther ones are hidden and
neighbours' spills raise a bin: only the floors stay sure.

:func:`cover` turns the floors into discs a barrier can hold on: per bin, the smallest disc
round the arc of radius ``floor_b`` across the bin. Every centre the bin may hold is at least
as far from the robot as that disc; once the robot has moved by ``delta`` from where the
lidar read, at most ``2 delta`` nearer than the disc (the docs' "the shield from what the
agent senses"). :func:`reading` is the lidar itself, for tests and for measuring the
estimate against MuJoCo's positions.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: Safety-Gymnasium's Goal tasks' lidar: bins, range (m), alias.
BINS = 16
MAX_DIST = 3.0
#: Two readings this close are one reading's alias spills summing to it (a clean triple):
#: Safety-Gymnasium's readings are exact to rounding, and a bin holding only a neighbour's
#: spill passes as clean only within this much of the shared edge, its distance then off by at
#: most ``max_dist * CLEAN``.
CLEAN = 1e-12


@dataclass(frozen=True)
class Lidar:
    """One pseudo-lidar's settings: ``bins`` sectors, read up to ``max_dist`` metres, with or
    without alias."""

    bins: int = BINS
    max_dist: float = MAX_DIST
    alias: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.bins, int) or self.bins < 3:
            raise ValueError(f"Lidar(bins={self.bins!r}): expected an int >= 3")
        if not np.isfinite(self.max_dist) or self.max_dist <= 0.0:
            raise ValueError(f"Lidar(max_dist={self.max_dist!r}): expected a finite range > 0")

    @cached_property
    def before(self) -> NDArray[np.intp]:
        """Per bin, the index of the bin before it (``b - 1``, modulo ``bins``): read every
        step, a gather costs far less than ``np.roll``."""
        return (np.arange(self.bins) - 1) % self.bins

    @cached_property
    def after(self) -> NDArray[np.intp]:
        """Per bin, the index of the bin after it (``b + 1``, modulo ``bins``)."""
        return (np.arange(self.bins) + 1) % self.bins

    @cached_property
    def starts(self) -> NDArray[np.float64]:
        """Per bin, the angle where it starts (rad, from the body's +x axis)."""
        return np.arange(self.bins) * self.width

    @property
    def width(self) -> float:
        """One bin's angle (rad)."""
        return 2.0 * np.pi / self.bins

    def check(self, obs: ArrayLike, where: str = "obs") -> NDArray[np.float64]:
        """``obs`` as this lidar's bins (a float array of ``bins`` values in ``[0, 1]``), or a
        ``ValueError`` naming what is wrong."""
        bins = np.asarray(obs, dtype=np.float64)
        if bins.shape != (self.bins,):
            raise ValueError(f"{where}: expected {self.bins} lidar bins, got shape {bins.shape}")
        # Read every step: two reductions, and NaN fails both comparisons.
        if not (bins.min() >= 0.0 and bins.max() <= 1.0):
            raise ValueError(f"{where}: lidar bins must lie in [0, 1], got {bins}")
        return bins


#: The Goal tasks' lidar.
GOAL_TASKS = Lidar()


def reading(points: ArrayLike, lidar: Lidar = GOAL_TASKS) -> NDArray[np.float64]:
    """The bins ``lidar`` reads of objects centred at ``points`` (``(k, 2)``, the body frame:
    metres, +x the body's x axis), as Safety-Gymnasium computes them."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    out = np.zeros(lidar.bins)
    for x, y in pts:
        d = float(np.hypot(x, y))
        s = max(0.0, lidar.max_dist - d) / lidar.max_dist
        ang = float(np.arctan2(y, x)) % (2.0 * np.pi)
        b = int(ang / lidar.width)
        # A point on the last bin's far edge reads as bin 0, as atan2's 2 pi wraps to 0.
        b %= lidar.bins
        out[b] = max(out[b], s)
        if lidar.alias:
            a = ang / lidar.width - int(ang / lidar.width)
            out[(b + 1) % lidar.bins] = max(out[(b + 1) % lidar.bins], a * s)
            out[(b - 1) % lidar.bins] = max(out[(b - 1) % lidar.bins], (1.0 - a) * s)
    return out


def floors(obs: ArrayLike, lidar: Lidar = GOAL_TASKS) -> NDArray[np.float64]:
    """Per bin, the distance (m) no centre in that bin is nearer than: ``max_dist (1 - obs)``
    (``max_dist`` where the bin reads 0: nothing is seen)."""
    bins = lidar.check(obs)
    return lidar.max_dist * (1.0 - bins)


def arcs(
    obs: ArrayLike, lidar: Lidar = GOAL_TASKS
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per bin, the angles ``lo <= hi`` (rad, from the body's +x axis, within the bin) between
    which a centre at the bin's floor lies, if the bin holds one there. Such a centre's reading
    ``s`` is the bin's, and its spills ``a s`` and ``(1 - a) s`` are at most the neighbours'
    readings, so ``1 - obs[b - 1] / s <= a <= obs[b + 1] / s``: one angle where the bin is
    clean, the whole bin where it reads 0 or without alias. (Farther centres may lie anywhere
    in the bin; only the floor is sure.)"""
    bins = lidar.check(obs)
    start = lidar.starts
    if not lidar.alias:
        return start, start + lidar.width
    seen = bins > 0.0
    s = np.where(seen, bins, 1.0)
    # Clipped to [0, 1] by maximum then minimum: read every step, and np.clip costs more.
    lo = np.where(seen, np.minimum(np.maximum(1.0 - bins[lidar.before] / s, 0.0), 1.0), 0.0)
    hi = np.where(seen, np.minimum(np.maximum(bins[lidar.after] / s, 0.0), 1.0), 1.0)
    # Rounding may cross a clean bin's two bounds (equal in exact arithmetic).
    lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
    return start + lo * lidar.width, start + hi * lidar.width


def nearest(obs: ArrayLike, lidar: Lidar = GOAL_TASKS) -> tuple[float, float] | None:
    """The one object of a lidar that sees a single object (the goal's): its distance (m) and
    its angle from the body's +x axis (rad, counter-clockwise, in ``[0, 2 pi)``), exact where
    its bin and both neighbours hold only its readings. ``None`` where every bin reads 0 (the
    object is ``max_dist`` or farther away). Without alias the angle is the bin's centre
    (within half a bin)."""
    bins = lidar.check(obs)
    b = int(np.argmax(bins))
    s = float(bins[b])
    if s <= 0.0:
        return None
    d = lidar.max_dist * (1.0 - s)
    if not lidar.alias:
        return d, (b + 0.5) * lidar.width
    # Alias: the next bin holds a s, the previous (1 - a) s; the larger of the two is the
    # better conditioned (a tie, a = 1/2, reads the same either way).
    after, before = float(bins[(b + 1) % lidar.bins]), float(bins[(b - 1) % lidar.bins])
    a = after / s if after >= before else 1.0 - before / s
    return d, ((b + min(max(a, 0.0), 1.0)) * lidar.width) % (2.0 * np.pi)


def clean(obs: ArrayLike, b: int, lidar: Lidar = GOAL_TASKS) -> bool:
    """Whether bin ``b`` and its neighbours hold one object's readings alone (its alias spills
    sum to its own reading; another object would only raise a neighbour)."""
    bins = lidar.check(obs)
    s = float(bins[b])
    if not lidar.alias or s <= 0.0:
        return False
    spills = float(bins[(b + 1) % lidar.bins] + bins[(b - 1) % lidar.bins])
    return abs(spills - s) <= CLEAN


#: Discs per bin: centres ``(bins, 2)`` and radii ``(bins,)``.
Discs = tuple[NDArray[np.float64], NDArray[np.float64]]


def cover(obs: ArrayLike, lidar: Lidar = GOAL_TASKS) -> Discs:
    """Per bin, the disc a barrier holds on for what the bin may hold: its centre (``(bins, 2)``,
    the body frame) and radius (``(bins,)``), the smallest disc round the arc of radius
    ``floor_b`` across the bin (centre ``floor_b cos(B / 2)`` along the bin's middle, radius
    ``floor_b sin(B / 2)``). A bin that reads 0 gets the same disc at ``max_dist``.

    Every centre the bin may hold is at least as far from the lidar's origin as the disc, and
    from any point ``delta`` away from the origin at most ``2 delta`` nearer than the disc."""
    r = floors(obs, lidar)
    half = 0.5 * lidar.width
    mid = (np.arange(lidar.bins) + 0.5) * lidar.width
    centres = (r * np.cos(half))[:, None] * np.column_stack([np.cos(mid), np.sin(mid)])
    return centres, r * np.sin(half)
