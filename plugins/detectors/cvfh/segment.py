"""Scene preparation shared by the depth detectors: input checks, table removal, clustering.

The cloud is in the world frame (metres, z up) with the table below the part.
Every failure is returned as a reason string (the detector reports
``found: false`` with it), never raised: a bad cloud is an outcome of
detection, not a crash.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydantic import Field

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core.models import StrictModel, TablePlane

import open3d as o3d  # isort: skip

__all__ = [
    "Scene",
    "SegmentSettings",
    "check_cloud",
    "cluster_objects",
    "merge_nearby",
    "remove_table",
    "to_o3d",
]

# A depth camera sees a few metres at most; a cloud spanning more than this
# many "metres" is almost surely written in millimetres.
MAX_PLAUSIBLE_EXTENT = 30.0


class SegmentSettings(StrictModel):
    """Table removal and clustering (metres)."""

    plane_voxel: float = Field(0.01, gt=0.0, description="voxel size of the cloud the table plane is fitted on")
    plane_distance: float = Field(0.006, gt=0.0, description="RANSAC inlier distance to the table plane")
    plane_iterations: int = Field(300, ge=10, description="RANSAC iterations of the plane fit")
    plane_min_fraction: float = Field(0.2, gt=0.0, le=1.0, description="least share of points on the table")
    max_tilt_deg: float = Field(30.0, gt=0.0, le=90.0, description="largest angle between table normal and +z")
    min_height: float = Field(0.007, ge=0.0, description="points lower than this above the table are table")
    max_height: float = Field(0.5, gt=0.0, description="points higher than this above the table are ignored")
    cluster_voxel: float = Field(0.002, gt=0.0, description="voxel size of the points that are clustered")
    cluster_eps: float = Field(0.008, gt=0.0, description="DBSCAN neighbourhood radius")
    cluster_min_points: int = Field(8, ge=1, description="DBSCAN core-point neighbour count")
    min_cluster_points: int = Field(60, ge=3, description="smaller clusters are noise")
    merge_gap: float = Field(
        0.06,
        ge=0.0,
        description="clusters this close are merged when the union still fits the part (self-occlusion"
        " splits a part: an L-block's upright hides the middle of its foot)",
    )


@dataclass
class Scene:
    """A prepared scene: the valid points, the table and the candidate object clusters."""

    points: np.ndarray
    """(n, 3) finite points, world frame, metres."""
    table: TablePlane
    above: np.ndarray
    """(m, 3) points between min_height and max_height above the table."""
    clusters: list[np.ndarray] = field(default_factory=list)
    """Candidate objects, largest first: (k, 3) points each (voxel-downsampled)."""


def to_o3d(points: np.ndarray, normals: np.ndarray | None = None) -> o3d.geometry.PointCloud:
    """An Open3D point cloud of ``(n, 3)`` points (and normals)."""
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.ascontiguousarray(points, dtype=np.float64)))
    if normals is not None:
        pc.normals = o3d.utility.Vector3dVector(np.ascontiguousarray(normals, dtype=np.float64))
    return pc


def check_cloud(cloud: np.ndarray) -> tuple[np.ndarray | None, str | None]:
    """Drop non-finite rows; return ``(points, None)`` or ``(None, reason)``."""
    arr = np.asarray(cloud, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3:
        return None, f"the cloud must be an (n, 3) array of points, got shape {arr.shape}"
    pts = arr[np.all(np.isfinite(arr), axis=1)]
    if len(pts) == 0:
        what = "empty" if len(arr) == 0 else "all NaN or infinite"
        return None, f"the cloud is {what}: no valid points to detect in"
    sample = pts[:: max(1, len(pts) // 20000)]  # percentiles of a stride sample: cheap and robust enough
    lo, hi = np.percentile(sample, [1, 99], axis=0)
    extent = float(np.max(hi - lo))
    if extent > MAX_PLAUSIBLE_EXTENT:
        return None, (
            f"the cloud spans {extent:.0f} units; it looks like millimetres. Give it in metres (scale by 0.001)"
        )
    return pts, None


def remove_table(
    points: np.ndarray,
    settings: SegmentSettings,
    *,
    table: TablePlane | None = None,
    seed: int = 0,
) -> tuple[TablePlane | None, np.ndarray | None, str | None]:
    """Fit (or take) the table plane; return ``(table, points above it, reason)``.

    The plane is fitted with Open3D's RANSAC on a voxel-downsampled copy, then
    refined by least squares on every point near it so the table height is
    precise to well under a millimetre.
    """
    if table is None:
        table, reason = _fit_table(points, settings, seed)
        if table is None:
            return None, None, reason
    n = np.asarray(table.normal, dtype=float)
    n = n / np.linalg.norm(n)
    h = points @ n - table.height
    above = points[(h > settings.min_height) & (h < settings.max_height)]
    if len(above) < settings.min_cluster_points:
        return (
            table,
            None,
            (
                f"nothing stands on the table: only {len(above)} points are {settings.min_height * 1000:.0f} mm to "
                f"{settings.max_height:.2f} m above it"
            ),
        )
    return table, above, None


def _fit_table(points: np.ndarray, s: SegmentSettings, seed: int) -> tuple[TablePlane | None, str | None]:
    if len(points) < 3:
        return None, "no table plane: the cloud has fewer than 3 points"
    down = to_o3d(points).voxel_down_sample(s.plane_voxel)
    if len(down.points) < 3:
        return None, "no table plane: the cloud collapses to fewer than 3 voxels"
    # Open3D's RANSAC draws from its own global generator; seed it for repeatable runs.
    o3d.utility.random.seed(int(seed))
    model, inliers = down.segment_plane(s.plane_distance, 3, s.plane_iterations)
    frac = len(inliers) / len(down.points)
    if frac < s.plane_min_fraction:
        return None, (
            f"no table plane: the best plane holds {100 * frac:.0f}% of the cloud "
            f"(need {100 * s.plane_min_fraction:.0f}%); the camera must see the table around the part"
        )
    normal = np.asarray(model[:3], dtype=float)
    d = float(model[3])
    scale = float(np.linalg.norm(normal))
    normal, d = normal / scale, d / scale
    if normal[2] < 0:
        normal, d = -normal, -d
    tilt = float(np.degrees(np.arccos(np.clip(normal[2], -1.0, 1.0))))
    if tilt > s.max_tilt_deg:
        return None, (
            f"no table plane: the largest plane is tilted {tilt:.0f} deg from horizontal; "
            "give the cloud in the world frame with z up"
        )
    # Least-squares refinement on (a stride sample of) the full-resolution inliers.
    sample = points[:: max(1, len(points) // 50000)]
    near = sample[np.abs(sample @ normal + d) < s.plane_distance]
    if len(near) >= 3:
        c = near.mean(axis=0)
        q = near - c
        _, vecs = np.linalg.eigh(q.T @ q)  # smallest-eigenvalue eigenvector = plane normal
        n2 = vecs[:, 0] if vecs[2, 0] > 0 else -vecs[:, 0]
        normal, d = n2, -float(n2 @ c)
    return TablePlane(height=-d, normal=normal), None


def cluster_objects(above: np.ndarray, settings: SegmentSettings) -> list[np.ndarray]:
    """Euclidean clusters (Open3D DBSCAN) of the points above the table, largest first."""
    down = to_o3d(above).voxel_down_sample(settings.cluster_voxel)
    pts = np.asarray(down.points)
    if len(pts) < settings.min_cluster_points:
        return []
    labels = np.asarray(down.cluster_dbscan(settings.cluster_eps, settings.cluster_min_points))
    out = [pts[labels == k] for k in range(labels.max() + 1)]
    out = [c for c in out if len(c) >= settings.min_cluster_points]
    out.sort(key=len, reverse=True)
    return out


def merge_nearby(clusters: list[np.ndarray], gap: float, max_width: float) -> list[np.ndarray]:
    """Merge clusters closer than ``gap`` (metres, nearest points) while the union stays ``max_width`` wide.

    Greedy, largest cluster first; returns the clusters largest first.
    """
    from scipy.spatial import cKDTree

    pending = sorted(clusters, key=len, reverse=True)
    out: list[np.ndarray] = []
    while pending:
        current = pending.pop(0)
        grown = True
        while grown:
            grown = False
            tree = cKDTree(current)
            for i, other in enumerate(pending):
                d, _ = tree.query(other, k=1, distance_upper_bound=gap)
                if not np.isfinite(d).any():
                    continue
                union = np.vstack([current, other])
                if float(np.linalg.norm(np.ptp(union, axis=0))) <= max_width:
                    current = union
                    pending.pop(i)
                    grown = True
                    break
        out.append(current)
    out.sort(key=len, reverse=True)
    return out
