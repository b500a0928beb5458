"""Densify and re-check joint paths: joint-space steps or TCP displacement steps.

A planner's path is a polyline in joint space. Before execution (or for an
independent re-check) it is sampled so that consecutive configurations differ
by at most a joint-space step (:func:`densify`) or move the TCP by at most a
Cartesian step, e.g. 5 mm (:func:`densify_tcp`), and every sample is checked
(:func:`first_invalid`).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np

__all__ = ["densify", "densify_tcp", "first_invalid"]


def densify(path: np.ndarray, max_step: float) -> np.ndarray:
    """Insert evenly spaced points so consecutive rows differ by at most ``max_step``.

    Parameters
    ----------
    path : ``(n, dof)`` waypoints, radians.
    max_step : largest allowed Euclidean joint-space step, radians (> 0).

    Returns ``(m, dof)`` with ``m >= n``; every original waypoint is kept.
    """
    pts = np.atleast_2d(np.asarray(path, dtype=float))
    if not max_step > 0:
        raise ValueError(f"max_step must be > 0 (got {max_step})")
    if len(pts) < 2:
        return pts.copy()
    seg = np.diff(pts, axis=0)
    counts = np.maximum(1, np.ceil(np.linalg.norm(seg, axis=1) / max_step).astype(int))
    # For every segment k, fractions 0, 1/c_k, ..., (c_k - 1)/c_k; the last waypoint is appended.
    seg_idx = np.repeat(np.arange(len(seg)), counts)
    frac = (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)) / np.repeat(counts, counts)
    out = pts[seg_idx] + frac[:, None] * seg[seg_idx]
    return np.vstack([out, pts[-1:]])


def densify_tcp(
    path: np.ndarray,
    tcp_position: Callable[[np.ndarray], np.ndarray],
    max_step: float = 0.005,
    *,
    max_depth: int = 20,
) -> np.ndarray:
    """Subdivide each segment until the TCP moves at most ``max_step`` metres between samples.

    ``tcp_position(q)`` returns the TCP position ``(3,)`` in metres (e.g. the
    translation of ``robot.fk(arm, q)``). Segments are bisected, so the check is
    on the straight joint-space interpolation the controller executes; the
    distance is between the TCP positions of consecutive samples (a chord), which
    is what a 5 mm re-check asks for. ``max_depth`` bounds the bisection.
    """
    pts = np.atleast_2d(np.asarray(path, dtype=float))
    if not max_step > 0:
        raise ValueError(f"max_step must be > 0 (got {max_step})")
    out = [pts[0]]
    for a, b in itertools.pairwise(pts):
        stack = [(a, b, np.asarray(tcp_position(a)), np.asarray(tcp_position(b)), 0)]
        seg: list[np.ndarray] = []
        while stack:
            qa, qb, pa, pb, depth = stack.pop()
            if np.linalg.norm(pb - pa) <= max_step or depth >= max_depth:
                seg.append(qb)
                continue
            qm = 0.5 * (qa + qb)
            pm = np.asarray(tcp_position(qm))
            # Push the second half first so the first half is emitted first (in path order).
            stack.append((qm, qb, pm, pb, depth + 1))
            stack.append((qa, qm, pa, pm, depth + 1))
        out.extend(seg)
    return np.array(out)


def first_invalid(path: np.ndarray, is_valid: Callable[[np.ndarray], bool]) -> int:
    """Index of the first row of ``path`` for which ``is_valid`` is False, or -1 if all pass."""
    for i, q in enumerate(np.atleast_2d(path)):
        if not is_valid(q):
            return i
    return -1
