"""Every point of a scene labelled by the detectors' front end, and an organized cloud's mixed pixels.

What :mod:`~asmteach.core.perception.segment_score` scores (``benchmarks/mosd_segmentation.py`` on real
Kinect scenes): :func:`label_scene` runs :mod:`~asmteach.core.perception.segmentation` and gives each
point its cluster. Points are in the world frame (z up), metres, unless a docstring says otherwise.
"""

from __future__ import annotations

import numpy as np

from asmteach.core.clouds import depth_sigma
from asmteach.core.models import TablePlane
from asmteach.core.perception.segmentation import (
    SegmentSettings,
    above_mask,
    check_cloud,
    cluster_labels,
    remove_table,
    voxelize,
)

__all__ = ["image_index", "label_scene", "mixed_pixels"]


def label_scene(
    points: np.ndarray,
    settings: SegmentSettings,
    *,
    table: TablePlane | None = None,
    seed: int = 0,
    viewpoint: np.ndarray | None = None,
    image_shape: tuple[int, int] | None = None,
) -> tuple[TablePlane | None, np.ndarray, str | None]:
    """The whole front end as per-point labels: ``(table, labels, reason)``.

    ``points`` is ``(n, 3)``, world frame (z up), metres; NaN rows are allowed (an organized cloud's
    missing returns) and labelled 0. ``labels[i]`` is 0 for points in no object (no return, table, too
    high, noise) and ``k >= 1`` for the ``k``-th cluster of
    :func:`~asmteach.core.perception.segmentation.cluster_objects` (largest first): every point gets the
    cluster of its voxel. ``reason`` says why there is no table or nothing on it.

    ``image_shape`` ``(height, width)`` says the points are an organized cloud's pixels, row by row; with a
    ``viewpoint`` its mixed pixels (:func:`mixed_pixels`) are then left out of the objects.
    """
    pts_all = np.asarray(points, dtype=float)
    labels = np.zeros(len(pts_all), dtype=np.int64)
    finite = np.flatnonzero(np.all(np.isfinite(pts_all), axis=1)) if pts_all.ndim == 2 else np.zeros(0, int)
    pts, reason = check_cloud(pts_all)
    if pts is None:
        return None, labels, reason
    table, above, reason = remove_table(pts, settings, table=table, seed=seed, viewpoint=viewpoint)
    if table is None or above is None:
        return table, labels, reason
    keep = above_mask(pts, table, settings, viewpoint)
    if image_shape is not None and viewpoint is not None and settings.mixed_pixel_sigmas > 0:
        hh, ww = image_shape
        if hh * ww != len(pts_all):
            raise ValueError(f"image_shape {image_shape} does not match {len(pts_all)} points")
        mixed = mixed_pixels(pts_all.reshape(hh, ww, 3), viewpoint, settings.mixed_pixel_sigmas).reshape(-1)
        keep &= ~mixed[finite]
    idx = finite[keep]
    centres, inverse = voxelize(pts_all[idx], settings.cluster_voxel)
    vox = cluster_labels(centres, settings, viewpoint)
    labels[idx] = vox[inverse] + 1
    return table, labels, None


def image_index(
    points_cam: np.ndarray, fx: float, fy: float, cx: float, cy: float, width: int, height: int
) -> np.ndarray:
    """Per point its pixel in a ``height x width`` image (row-major index), or -1 (no return, outside).

    Puts an unorganized camera-frame cloud (OpenCV frame, metres) back on its sensor's image grid through
    the pinhole intrinsics (pixels), so organized-cloud steps (:func:`mixed_pixels`) apply to it.
    """
    p = np.asarray(points_cam, dtype=float)
    out = np.full(len(p), -1, dtype=np.int64)
    ok = np.all(np.isfinite(p), axis=1) & (p[:, 2] > 0)
    u = np.round(fx * p[ok, 0] / p[ok, 2] + cx).astype(np.int64)
    v = np.round(fy * p[ok, 1] / p[ok, 2] + cy).astype(np.int64)
    inside = (u >= 0) & (u < width) & (v >= 0) & (v < height)
    idx = np.flatnonzero(ok)[inside]
    out[idx] = v[inside] * width + u[inside]
    return out


def mixed_pixels(grid: np.ndarray, viewpoint: np.ndarray, sigmas: float = 3.0) -> np.ndarray:
    """``(h, w) bool``: the mixed pixels of an organized cloud ``grid`` (``(h, w, 3)``, metres, NaN = no return).

    A depth sensor's pixel on a depth edge mixes foreground and background and lands between them: a point
    floating in front of the background, near neither surface (on a real Kinect it sticks to the table
    beside an object, up to ~2 cm above it). Along a row or a column such a pixel ``p`` steps in range by
    more than ``sigmas`` depth-noise sigmas (:func:`asmteach.core.clouds.depth_sigma` at its range from
    ``viewpoint``, the camera centre in the grid's frame) to both neighbours, in the same direction, while
    each neighbour's own next step is less than half of that (flat ground on both sides: a steep surface
    steps evenly and is kept).
    """
    g = np.asarray(grid, dtype=float)
    r = np.linalg.norm(g - np.asarray(viewpoint, dtype=float), axis=2)  # NaN where no return
    tau = sigmas * depth_sigma(r)
    out = np.zeros(r.shape, dtype=bool)
    with np.errstate(invalid="ignore"):
        for rr in (r, r.T):
            t = tau if rr is r else tau.T
            a2, a1, c, b1, b2 = rr[:, :-4], rr[:, 1:-3], rr[:, 2:-2], rr[:, 3:-1], rr[:, 4:]
            d1, d2 = c - a1, b1 - c
            step = (np.abs(d1) > t[:, 2:-2]) & (np.abs(d2) > t[:, 2:-2]) & (np.sign(d1) == np.sign(d2))
            flat = (np.abs(a1 - a2) < 0.5 * np.abs(d1)) & (np.abs(b2 - b1) < 0.5 * np.abs(d2))
            hit = np.zeros(rr.shape, dtype=bool)
            hit[:, 2:-2] = step & flat
            out |= hit if rr is r else hit.T
    return out
