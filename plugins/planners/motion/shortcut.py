"""Path shortening with batched validity checks: greedy vertex reduction, then random shortcuts.

OMPL's ``og.PathSimplifier`` checks one state per python callback (about 4,700
callbacks for an 18-waypoint 6-D path, ~800 even for a 3-waypoint one); on a
robot whose single-configuration check costs ~1 ms that is seconds per query.
When the validity callable has a vectorised ``batch(qs)`` (see :mod:`.batch`),
:func:`shorten` does the same job with a few dozen batched calls:

1. vertex reduction: from each kept waypoint, jump to the farthest later
   waypoint the straight segment reaches (binary search over the candidates);
2. ``attempts`` random shortcuts between two points anywhere on the path
   (positions by arc length, drawn from the caller's generator), kept when valid
   and shorter.

A segment is checked at the motion resolution coarse to fine (every 8th state
first, so most blocked segments cost one small call). With a ``cost`` and a
``ceiling``, a new segment must also stay at or below the ceiling (sampled at
4x the resolution: the ceiling is a clearance preference, the collision check
is the safety one); that test comes between the coarse and the fine states,
since on the assembly planner's paths a third of the shortcuts fail it and
almost none fail the fine states. Every returned segment was checked; end
points are kept.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

__all__ = ["SegmentChecker", "shorten"]


class SegmentChecker:
    """Straight joint-space segments checked in batches (radians; ``valid_batch(qs) -> (n,) bool``)."""

    def __init__(
        self,
        valid_batch: Callable[[np.ndarray], np.ndarray],
        resolution: float,
        *,
        cost_batch: Callable[[np.ndarray], np.ndarray] | None = None,
        ceiling: float = math.inf,
        coarse: int = 8,
        cost_every: int = 4,
    ) -> None:
        self.valid_batch = valid_batch
        self.resolution = float(resolution)
        self.cost_batch = cost_batch
        self.ceiling = float(ceiling)
        self.coarse = int(coarse)
        self.cost_every = int(cost_every)
        self.calls = 0
        self.cost_calls = 0
        self.states = 0

    def _valid(self, qs: np.ndarray) -> bool:
        if len(qs) == 0:
            return True
        self.calls += 1
        self.states += len(qs)
        return bool(np.all(np.asarray(self.valid_batch(qs), dtype=bool)))

    def __call__(self, qa: np.ndarray, qb: np.ndarray) -> bool:
        """True when every state strictly between ``qa`` and ``qb`` (ends assumed checked) passes."""
        k = math.ceil(float(np.linalg.norm(qb - qa)) / self.resolution)
        if k <= 1:
            return True
        frac = np.arange(1, k) / k
        pts = qa + frac[:, None] * (qb - qa)
        first = np.zeros(len(pts), dtype=bool)
        first[:: self.coarse] = True
        if not self._valid(pts[first]):
            return False
        # The cost before the remaining states: a shortcut that clears the obstacles mostly fails, when it
        # fails, by passing nearer to them than the path it replaces.
        if self.cost_batch is not None and math.isfinite(self.ceiling):
            self.cost_calls += 1
            if not np.all(np.asarray(self.cost_batch(pts[:: self.cost_every]), dtype=float) <= self.ceiling):
                return False
        return self._valid(pts[~first])


def _length(path: np.ndarray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))


def _reduce_vertices(path: np.ndarray, segment_ok: SegmentChecker) -> np.ndarray:
    out = [0]
    i = 0
    n = len(path)
    while i < n - 1:
        # Binary search for the farthest reachable waypoint; i + 1 is always reachable (an edge of the path).
        lo, hi = i + 1, n - 1
        if segment_ok(path[i], path[hi]):
            lo = hi
        else:
            while hi - lo > 1:
                mid = (lo + hi) // 2
                if segment_ok(path[i], path[mid]):
                    lo = mid
                else:
                    hi = mid
        out.append(lo)
        i = lo
    return path[out]


def _point_at(path: np.ndarray, cum: np.ndarray, s: float) -> tuple[int, np.ndarray]:
    """Segment index and point at arc length ``s`` along ``path``."""
    k = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(path) - 2))
    seg = cum[k + 1] - cum[k]
    t = 0.0 if seg <= 0 else (s - cum[k]) / seg
    return k, path[k] + t * (path[k + 1] - path[k])


def shorten(
    path: np.ndarray,
    segment_ok: SegmentChecker,
    rng: np.random.Generator,
    *,
    attempts: int = 30,
) -> np.ndarray:
    """Shorten ``path`` ``(n, dof)`` (a valid path) keeping its end points; see the module doc."""
    pts = np.asarray(path, dtype=float)
    if len(pts) < 3:
        return pts.copy()
    pts = _reduce_vertices(pts, segment_ok)
    for _ in range(attempts):
        if len(pts) < 3 and _length(pts) <= 0:
            break
        cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
        s1, s2 = np.sort(rng.uniform(0.0, cum[-1], size=2))
        k1, a = _point_at(pts, cum, s1)
        k2, b = _point_at(pts, cum, s2)
        if k1 == k2:
            continue  # both on one straight segment: nothing to gain
        # Shorter only if the chord beats the path between the two points (always, unless collinear).
        if np.linalg.norm(b - a) >= (s2 - s1) - 1e-9:
            continue
        # The new points a and b lie on checked segments, so only the chord needs checking.
        if segment_ok(a, b):
            pts = np.vstack([pts[: k1 + 1], a[None], b[None], pts[k2 + 1 :]])
    # Drop the zero-length steps the cuts may leave (a cut ending exactly on a waypoint).
    out = [pts[0]]
    for q in pts[1:]:
        if np.linalg.norm(q - out[-1]) > 1e-9:
            out.append(q)
    out[-1] = pts[-1] if len(out) > 1 else out[-1]
    if len(out) == 1:
        out.append(pts[-1])
    return np.array(out)
