"""A joint polyline with its corners rounded by circular arcs, as a path toppra can time.

Each corner is rounded by an arc in joint space tangent to both segments,
taking at most half of each, whose distance from the corner (its largest
distance from the polyline) is at most the corner's ``deviation`` radians
(Euclidean joint-space norm); see :mod:`.blended` for why, and for the timing.
The path is parametrised by arc length (radians).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import toppra

__all__ = ["MIN_TURN", "BlendedPath", "Piece"]

MIN_TURN = 1e-9  # rad: a smaller turn between segments is no corner


@dataclass
class Piece:
    """A line (``radius == 0``) or circular arc of a blended path, starting at path position ``s0``."""

    s0: float
    length: float
    p0: np.ndarray  # line: start point; arc: centre
    u: np.ndarray  # line: unit direction; arc: unit vector from the centre to the arc's start
    v: np.ndarray  # arc: unit tangent at the start (unused for a line)
    radius: float = 0.0


class BlendedPath(toppra.interpolator.AbstractGeometricPath):
    """A joint path of straight segments with circular corner blends, parametrised by arc length (rad).

    ``waypoints`` ``(n, dof)`` radians; ``deviation[i]`` (rad) bounds the
    blend at interior waypoint ``i`` (0: keep the corner sharp; such a corner
    must be a stop, see :func:`time_optimal`). Positions are exact on lines
    and arcs; ``__call__(s, 1)`` is the unit tangent and ``__call__(s, 2)`` the
    curvature vector (1/rad), 0 on lines.
    """

    def __init__(self, waypoints: np.ndarray, deviation: np.ndarray) -> None:
        pts = np.asarray(waypoints, float)
        self._dof = pts.shape[1]
        self._waypoints = pts
        d = np.diff(pts, axis=0)
        lengths = np.linalg.norm(d, axis=1)
        units = d / lengths[:, None]
        cut = np.zeros(len(pts))  # distance from each waypoint to where its blend starts and ends
        self.arcs: list[tuple[int, float]] = []  # (waypoint index, radius) of every blend
        arc_at: dict[int, tuple[float, float]] = {}
        for i in range(1, len(pts) - 1):
            turn = float(np.arccos(np.clip(units[i - 1] @ units[i], -1.0, 1.0)))
            # Two equal unit vectors can still give a dot product just below 1 and so a turn of ~2e-8 rad:
            # no corner there (its bisector is zero and the arc's centre would be NaN).
            if turn < MIN_TURN or deviation[i] <= 0.0 or not np.any(units[i] != units[i - 1]):
                continue
            half = 0.5 * turn
            # the arc's distance from the corner is ell * (1 - cos(half)) / sin(half) = ell * tan(half / 2)
            ell = min(0.5 * lengths[i - 1], 0.5 * lengths[i], deviation[i] / np.tan(0.5 * half))
            radius = ell / np.tan(half)
            cut[i] = ell
            arc_at[i] = (radius, turn)
            self.arcs.append((i, radius))
        pieces: list[Piece] = []
        s = 0.0
        for i in range(len(pts) - 1):
            start = pts[i] + cut[i] * units[i]
            length = lengths[i] - cut[i] - cut[i + 1]
            if length > 1e-12:
                pieces.append(Piece(s, length, start, units[i], units[i]))
                s += length
            if i + 1 in arc_at:
                radius, turn = arc_at[i + 1]
                a, b = units[i], units[i + 1]
                bis = b - a
                centre = pts[i + 1] + bis / np.linalg.norm(bis) * radius / np.cos(0.5 * turn)
                begin = pts[i + 1] - cut[i + 1] * a
                pieces.append(Piece(s, radius * turn, centre, (begin - centre) / radius, a, radius))
                s += radius * turn
        self._pieces = pieces
        self._starts = np.array([p.s0 for p in pieces])
        self._length = s
        self._end = pts[-1].copy()

    @property
    def dof(self) -> int:
        return self._dof

    @property
    def path_interval(self) -> np.ndarray:
        return np.array([0.0, self._length])

    @property
    def waypoints(self) -> np.ndarray:
        return self._waypoints

    @property
    def junctions(self) -> np.ndarray:
        """Path positions (rad) where pieces meet, ends included."""
        return np.append(self._starts, self._length)

    def pieces(self) -> list[Piece]:
        """The lines and arcs, in order."""
        return list(self._pieces)

    def __call__(self, path_positions: float | np.ndarray, order: int = 0) -> np.ndarray:
        scalar = np.ndim(path_positions) == 0
        ss = np.clip(np.atleast_1d(np.asarray(path_positions, float)), 0.0, self._length)
        idx = np.clip(np.searchsorted(self._starts, ss, side="right") - 1, 0, len(self._pieces) - 1)
        out = np.zeros((len(ss), self._dof))
        for k in np.unique(idx):
            p = self._pieces[k]
            m = idx == k
            t = (ss[m] - p.s0)[:, None]
            if p.radius == 0.0:
                if order == 0:
                    out[m] = p.p0 + t * p.u
                elif order == 1:
                    out[m] = p.u
                continue  # order 2: a line has no curvature
            th = t / p.radius
            c, sn = np.cos(th), np.sin(th)
            if order == 0:
                out[m] = p.p0 + p.radius * (c * p.u + sn * p.v)
            elif order == 1:
                out[m] = -sn * p.u + c * p.v
            elif order == 2:
                out[m] = -(c * p.u + sn * p.v) / p.radius
        if order == 0 and ss[-1] >= self._length:
            out[ss >= self._length] = self._end  # the last waypoint exactly, no rounding drift
        return out[0] if scalar else out

    def arc_samples(self, step: float) -> list[tuple[int, np.ndarray]]:
        """``(waypoint index, (m, dof) configurations)`` along each blend, at most ``step`` rad apart."""
        out = []
        arcs = iter(self.arcs)
        for p in self._pieces:
            if p.radius == 0.0:
                continue
            i, _ = next(arcs)
            n = 2 * int(np.ceil(0.5 * p.length / step)) + 1  # odd: the arc's middle, its farthest point, is in
            out.append((i, self(np.linspace(p.s0, p.s0 + p.length, n))))
        return out
