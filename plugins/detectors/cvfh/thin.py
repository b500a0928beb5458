"""Thin parts: the points of a part lower than the table-removal height, told from the table by local means.

A plate 3 mm thick lies below ``SegmentSettings.min_height`` (7 mm) everywhere, and a per-point
threshold cannot be lowered to it: the Kinect's depth noise puts one table point in eight more than
1.5 mm above the table. The mean height of a small patch is far steadier: the points are binned in
``cell``-sized squares of the table plane, and a point is *raised* when the mean height of its square and
the 8 around it (about 30 points at 1 m) is more than ``sigmas`` times that mean's spread over the table.
The spread is measured on the frame itself (the robust spread of the patch means of the points near the
table), so the threshold follows the sensor's noise rather than a number tuned to one scene.

Frames: points in the world frame, metres; heights along the table normal.
"""

from __future__ import annotations

import numpy as np

from asmteach.core.models import TablePlane
from asmteach.core.perception.segmentation import heights

__all__ = ["raised_mask"]


def raised_mask(
    points: np.ndarray, table: TablePlane, low: float, high: float, cell: float, sigmas: float
) -> tuple[np.ndarray, float]:
    """``(mask, threshold)``: the ``(n, 3)`` points whose patch stands clearly above the table.

    Only points below ``low`` metres (the ordinary table-removal height) can be raised by it, none above
    ``high``; ``threshold`` is the patch-mean height (metres) a patch had to exceed.
    """
    h = heights(points, table)
    n = np.asarray(table.normal, dtype=float)
    n = n / np.linalg.norm(n)
    u = np.cross(n, [0.0, 1.0, 0.0] if abs(n[0]) > 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    band = np.flatnonzero(h < low)
    p = points[band]
    ij = np.floor(np.stack([p @ u, p @ v], axis=1) / cell).astype(np.int64)
    ij -= ij.min(axis=0) - 1  # keys stay non-negative with a free ring for the neighbour offsets
    width = int(ij[:, 1].max()) + 2
    key = ij[:, 0] * width + ij[:, 1]
    cells, inverse = np.unique(key, return_inverse=True)
    total = np.bincount(inverse, h[band])
    count = np.bincount(inverse).astype(float)
    s, c = total.copy(), count.copy()
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di == dj == 0:
                continue
            other = cells + di * width + dj
            at = np.clip(np.searchsorted(cells, other), 0, len(cells) - 1)
            hit = cells[at] == other
            s[hit] += total[at[hit]]
            c[hit] += count[at[hit]]
    mean = (s / c)[inverse]
    # The table is most of the band: the median absolute deviation of the patch means is their spread there.
    centre = float(np.median(mean))
    spread = 1.4826 * float(np.median(np.abs(mean - centre)))
    threshold = centre + sigmas * spread
    mask = np.zeros(len(points), dtype=bool)
    mask[band[mean > threshold]] = True
    mask |= (h >= low) & (h < high)
    return mask, threshold
