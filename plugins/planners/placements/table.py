"""The table: its frame from a :class:`TablePlane`, and fitting the plane to a cloud.

Table frame: origin on the plane (the foot of the world origin), z along the
plane's upward normal, x along the world x axis projected on the plane (world
y when x is nearly normal to it). With a horizontal table at height ``h`` it
is the world frame shifted up by ``h``.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d

from asmteach.core.errors import UserError
from asmteach.core.models import TablePlane

__all__ = ["fit_table_plane", "points_above", "table_frame"]


def table_frame(table: TablePlane) -> np.ndarray:
    """``T_world_table`` (4x4, metres) of a table plane ``normal . p = height`` (world frame)."""
    n = np.asarray(table.normal, dtype=float)
    n = n / np.linalg.norm(n)
    ref = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = ref - (ref @ n) * n
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, 0] = x
    T[:3, 1] = np.cross(n, x)
    T[:3, 2] = n
    T[:3, 3] = table.height * n
    return T


def points_above(cloud: np.ndarray, table: TablePlane, band: float) -> np.ndarray:
    """Rows of ``cloud`` (world, metres) more than ``band`` metres above the table, NaN rows dropped."""
    pts = np.asarray(cloud, dtype=float).reshape(-1, 3)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    n = np.asarray(table.normal, dtype=float) / np.linalg.norm(table.normal)
    return pts[pts @ n - table.height > band]


def fit_table_plane(
    cloud: np.ndarray,
    *,
    up: np.ndarray = np.array([0.0, 0.0, 1.0]),  # noqa: B008 - read-only constant
    distance_threshold: float = 0.003,
    max_tilt_deg: float = 30.0,
    min_inlier_fraction: float = 0.05,
    max_below_fraction: float = 0.02,
    max_planes: int = 5,
    seed: int = 0,
) -> TablePlane:
    """Fit the table plane to a world-frame cloud with Open3D RANSAC (``segment_plane``).

    Planes are peeled off one after another (at most ``max_planes``); the
    table is the largest plane within ``max_tilt_deg`` of ``up`` that has
    almost nothing below it (at most ``max_below_fraction`` of the points more
    than ``3 * distance_threshold`` under it), which rules out the top face of
    a part. The plane is refined by least squares on its inliers.

    Raises :class:`UserError` when no such plane exists.
    """
    pts = np.asarray(cloud, dtype=float).reshape(-1, 3)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) < 50:
        raise UserError(f"cannot fit the table plane: the cloud has only {len(pts)} finite points")
    up = np.asarray(up, dtype=float) / np.linalg.norm(up)
    o3d.utility.random.seed(int(seed))  # Open3D's RANSAC draws from its own global generator
    remaining = np.arange(len(pts))
    best: tuple[int, np.ndarray, float] | None = None
    for _ in range(max_planes):
        if len(remaining) < max(50, min_inlier_fraction * len(pts)):
            break
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts[remaining]))
        model, inl = pcd.segment_plane(distance_threshold, 3, 1000)
        inl = np.asarray(inl, dtype=np.int64)
        if len(inl) < min_inlier_fraction * len(pts):
            break
        idx = remaining[inl]
        # Least-squares refinement: the smallest principal direction of the inliers.
        centre = pts[idx].mean(axis=0)
        normal = np.linalg.svd(pts[idx] - centre, full_matrices=False)[2][-1]
        if normal @ up < 0:
            normal = -normal
        height = float(normal @ centre)
        tilt = np.degrees(np.arccos(np.clip(normal @ up, -1.0, 1.0)))
        below = np.mean(pts @ normal - height < -3 * distance_threshold)
        if tilt <= max_tilt_deg and below <= max_below_fraction and (best is None or len(idx) > best[0]):
            best = (len(idx), normal, height)
        remaining = np.setdiff1d(remaining, idx, assume_unique=True)
        del model
    if best is None:
        raise UserError(
            "no table plane found in the cloud (no large plane facing up with the points above it); "
            "give the table height in the config"
        )
    return TablePlane(height=best[2], normal=best[1])
