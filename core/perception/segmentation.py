"""Scene preparation shared by the depth detectors: input checks, table removal, clustering.

The cloud is in the world frame (metres, z up) with the table below the part.
Every failure is returned as a reason string (the detector reports
``found: false`` with it), never raised: a bad cloud is an outcome of
detection, not a crash.

The detectors call :func:`check_cloud`, :func:`remove_table`, :func:`cluster_objects`
and :func:`merge_nearby`. :func:`~asmteach.core.perception.scene_labels.label_scene`
runs the same front end and labels every point (what
:mod:`~asmteach.core.perception.segment_score` and ``benchmarks/mosd_segmentation.py``
score on real Kinect scenes); for scenes of unknown objects it can also cut clusters at
concave creases (:func:`~asmteach.core.perception.concave.split_concave`), drop an
organized cloud's mixed pixels (:func:`~asmteach.core.perception.scene_labels.mixed_pixels`)
and raise the table threshold with the depth noise (``min_height_sigmas``). Those are
off in the detectors' defaults.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydantic import Field

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core.models import StrictModel, TablePlane
from asmteach.core.perception.concave import split_concave
from asmteach.core.perception.open3d_tools import one_thread, to_o3d

import open3d as o3d  # isort: skip

__all__ = [
    "Scene",
    "SegmentSettings",
    "above_mask",
    "check_cloud",
    "cluster_labels",
    "cluster_objects",
    "heights",
    "merge_nearby",
    "remove_table",
    "voxelize",
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
    min_height_sigmas: float = Field(
        0.0,
        ge=0.0,
        description="with a known viewpoint, points lower than this many Kinect depth-noise sigmas at their range"
        " (asmteach.core.clouds.depth_sigma) are table too (0: min_height only); real Kinect frames bleed an"
        " object's depth into the table pixels beside it",
    )
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
    mixed_pixel_sigmas: float = Field(
        3.0,
        ge=0.0,
        description="in an organized cloud, a pixel whose range steps by more than this many depth-noise sigmas"
        " to both neighbours along a row or column, with flat ground on both sides, is a mixed pixel (between a"
        " foreground edge and the background; 0: keep them)",
    )
    local_table_cell: float = Field(
        0.0,
        ge=0.0,
        description="measure heights from the table around each point (median heights in squares of this"
        " side, 3 x 3 around it) instead of the fitted plane: a real table and a Kinect's depth are not flat"
        " to a millimetre over a metre (0: the plane)",
    )
    split_concave: bool = Field(
        False,
        description="split each cluster at its concave creases (objects that touch: a box on a box, a cup"
        " against a bowl). Off for the part detectors: a part's own concave edges (an L-block's inner corner,"
        " a hole) would cut it, and merge_nearby only partly undoes that; on for scenes of unknown objects",
    )
    normal_radius: float = Field(0.012, gt=0.0, description="radius of the neighbourhood a normal is fitted on")
    smooth_angle_deg: float = Field(
        12.0, gt=0.0, lt=90.0, description="neighbours whose normals differ less than this grow one smooth region"
    )
    max_curvature: float = Field(
        0.04,
        gt=0.0,
        le=1.0 / 3.0,
        description="surface variation (smallest eigenvalue share of the neighbourhood) above which a point is a"
        " crease and grows no region",
    )
    crease_rings: int = Field(
        2,
        ge=0,
        description="crease points are widened by this many rings of neighbours (2.5 cluster_voxel each)"
        " before smooth regions grow, so a thin bridge of noisy points does not join two objects",
    )
    concave_angle_deg: float = Field(
        20.0,
        gt=0.0,
        lt=90.0,
        description="adjacent regions whose boundary is concave by more than this normal angle stay apart",
    )
    patch_radius: float = Field(
        0.02, gt=0.0, description="regions' points this close to their shared boundary give its convexity"
    )
    min_region_points: int = Field(
        30, ge=1, description="smaller smooth regions join the neighbour they share most edges with"
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


def check_cloud(cloud: np.ndarray) -> tuple[np.ndarray | None, str | None]:
    """Drop non-finite rows; return ``(points, None)`` or ``(None, reason)``."""
    arr = np.asarray(cloud, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3:
        return None, f"the cloud must be an (n, 3) array of points, got shape {arr.shape}"
    finite = np.isfinite(arr)
    # A whole-array test first: a rendered or cleaned cloud is all finite, and the per-row test plus the copy
    # cost more than the rest of the checks.
    pts = arr if finite.all() else arr[finite.all(axis=1)]
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
    viewpoint: np.ndarray | None = None,
) -> tuple[TablePlane | None, np.ndarray | None, str | None]:
    """Fit (or take) the table plane; return ``(table, points above it, reason)``.

    The plane is fitted with Open3D's RANSAC on a voxel-downsampled copy, then
    refined by least squares on every point near it so the table height is
    precise to well under a millimetre. ``viewpoint`` (camera centre, world
    frame, metres) lets ``min_height_sigmas`` raise the height threshold with
    the depth noise at each point's range.
    """
    if table is None:
        table, reason = _fit_table(points, settings, seed)
        if table is None:
            return None, None, reason
    above = points[above_mask(points, table, settings, viewpoint)]
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
    # Open3D's RANSAC draws from its own global generator; seeded and on one thread it repeats.
    o3d.utility.random.seed(int(seed))
    with one_thread():
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
    # Least-squares refinement on (a stride sample of) the full-resolution inliers, repeated until the
    # inliers stop changing: the fixed point makes the plane a function of the points, not of the RANSAC
    # draw (a seed's draw differs between Open3D versions and, on parallel threads, between runs).
    sample = points[:: max(1, len(points) // 50000)]
    chosen = None
    for _ in range(10):
        mask = np.abs(sample @ normal + d) < s.plane_distance
        if mask.sum() < 3 or (chosen is not None and np.array_equal(mask, chosen)):
            break
        chosen = mask
        near = sample[mask]
        c = near.mean(axis=0)
        q = near - c
        _, vecs = np.linalg.eigh(q.T @ q)  # smallest-eigenvalue eigenvector = plane normal
        n2 = vecs[:, 0] if vecs[2, 0] > 0 else -vecs[:, 0]
        normal, d = n2, -float(n2 @ c)
    return TablePlane(height=-d, normal=normal), None


def voxelize(points: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """Voxel-grid downsampling that remembers where each point went.

    Returns ``(centres, inverse)``: the mean of the points of each occupied ``voxel``-sized cube (metres,
    the points' frame; the grid is Open3D's ``voxel_down_sample`` grid, anchored half a voxel below the
    smallest coordinate) and, per input point, the row of its centre.
    """
    pts = np.asarray(points, dtype=float)
    if len(pts) == 0:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    keys = np.floor((pts - (pts.min(axis=0) - 0.5 * voxel)) / voxel).astype(np.int64)
    _, inverse = np.unique(keys, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    count = np.bincount(inverse)
    centres = np.stack([np.bincount(inverse, weights=pts[:, k]) for k in range(3)], axis=1) / count[:, None]
    return centres, inverse


def cluster_labels(pts: np.ndarray, settings: SegmentSettings, viewpoint: np.ndarray | None) -> np.ndarray:
    """Per voxel centre (``(n, 3)``, world frame, metres): its cluster (0 = largest, ...) or -1 (noise, too small)."""
    if len(pts) < settings.min_cluster_points:
        return np.full(len(pts), -1, dtype=np.int64)
    labels = np.asarray(to_o3d(pts).cluster_dbscan(settings.cluster_eps, settings.cluster_min_points))
    if settings.split_concave and labels.max() >= 0:
        out = np.full(len(pts), -1, dtype=np.int64)
        nxt = 0
        for k in range(labels.max() + 1):
            idx = np.flatnonzero(labels == k)
            sub = split_concave(pts[idx], settings, viewpoint=viewpoint)
            ok = sub >= 0
            out[idx[ok]] = sub[ok] + nxt
            nxt += int(sub.max()) + 1 if ok.any() else 0
        labels = out
    sizes = np.bincount(labels[labels >= 0], minlength=max(int(labels.max()) + 1, 0))
    keep = np.flatnonzero(sizes >= settings.min_cluster_points)
    order = keep[np.argsort(-sizes[keep], kind="stable")]  # largest first
    rank = np.full(len(sizes) + 1, -1, dtype=np.int64)
    rank[order] = np.arange(len(order))
    return rank[labels]  # labels == -1 picks rank[-1] == -1


def cluster_objects(
    above: np.ndarray, settings: SegmentSettings, *, viewpoint: np.ndarray | None = None
) -> list[np.ndarray]:
    """Euclidean clusters (Open3D DBSCAN) of the points above the table, largest first.

    Each cluster is ``(k, 3)`` voxel centres (``cluster_voxel``, world frame, metres). With
    ``settings.split_concave`` each cluster is further cut at its concave creases (:func:`split_concave`);
    ``viewpoint`` (camera centre, world frame, metres) orients the normals that needs.
    """
    pts, _ = voxelize(above, settings.cluster_voxel)
    labels = cluster_labels(pts, settings, viewpoint)
    return [pts[labels == k] for k in range(int(labels.max()) + 1)]


def heights(points: np.ndarray, table: TablePlane) -> np.ndarray:
    """Signed height of each ``(n, 3)`` point above the ``table`` plane (metres, along its unit normal)."""
    n = np.asarray(table.normal, dtype=float)
    n = n / np.linalg.norm(n)
    # Written out: numpy's (n, 3) @ (3,) is ~3x slower on a Kinect frame's 300 000 points.
    return points[:, 0] * n[0] + points[:, 1] * n[1] + points[:, 2] * n[2] - table.height


def above_mask(
    points: np.ndarray, table: TablePlane, settings: SegmentSettings, viewpoint: np.ndarray | None
) -> np.ndarray:
    """Points between the lowest object height (min_height, or the depth noise there) and max_height."""
    from asmteach.core.clouds import depth_sigma

    h = heights(points, table)
    low = np.full(len(points), settings.min_height)
    if viewpoint is not None and settings.min_height_sigmas > 0:
        rng = np.linalg.norm(points - np.asarray(viewpoint, dtype=float), axis=1)
        low = np.maximum(low, settings.min_height_sigmas * depth_sigma(rng))
    if settings.local_table_cell > 0:
        h = h - _local_table(points, h, h <= low, table, settings.local_table_cell)
    return (h > low) & (h < settings.max_height)


def _local_table(points: np.ndarray, h: np.ndarray, on_table: np.ndarray, table: TablePlane, cell: float) -> np.ndarray:
    """Per point the height of the table around it above the fitted plane (metres).

    The table's points are binned in ``cell``-sized squares of the plane; a point's local table is the
    count-weighted mean of the median heights in its square and the 8 around it (squares with fewer than
    10 table points count for nothing; none around: 0, the plane).
    """
    n = np.asarray(table.normal, dtype=float)
    n = n / np.linalg.norm(n)
    u = np.cross(n, [0.0, 1.0, 0.0] if abs(n[0]) > 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    ij = np.floor(np.stack([points @ u, points @ v], axis=1) / cell).astype(np.int64)
    t_ij, t_h = ij[on_table], h[on_table]
    if len(t_h) == 0:
        return np.zeros(len(points))
    cells, inv, count = np.unique(t_ij, axis=0, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    order = np.lexsort((t_h, inv))  # by square, then by height: each square's median is its middle row
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    med = t_h[order][start + count // 2]
    weight = np.where(count >= 10, count, 0).astype(float)
    lookup = {tuple(c): k for k, c in enumerate(cells.tolist())}
    acc = np.zeros(len(points))
    wsum = np.zeros(len(points))
    keys, back = np.unique(ij, axis=0, return_inverse=True)
    back = back.reshape(-1)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            k = np.array([lookup.get((a + di, b + dj), -1) for a, b in keys.tolist()], dtype=np.int64)
            w = np.where(k >= 0, weight[np.maximum(k, 0)], 0.0)
            acc += (w * med[np.maximum(k, 0)])[back]
            wsum += w[back]
    return np.where(wsum > 0, acc / np.maximum(wsum, 1e-12), 0.0)


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
