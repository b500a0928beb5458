"""Cut a cluster at its concave creases: a model-free split of objects that touch.

Used by :func:`~asmteach.core.perception.segmentation.cluster_objects` when
``SegmentSettings.split_concave`` is on (scenes of unknown objects; off for the part detectors).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core.perception.open3d_tools import to_o3d

import open3d as o3d  # isort: skip

if TYPE_CHECKING:  # segmentation imports this module for its clustering
    from asmteach.core.perception.segmentation import SegmentSettings

__all__ = ["split_concave"]


def _normals(pts: np.ndarray, radius: float, viewpoint: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals toward the viewpoint (else away from the centroid) and surface variation per point."""
    pc = to_o3d(pts)
    param = o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=40)
    pc.estimate_normals(param)
    pc.estimate_covariances(param)
    ev = np.linalg.eigvalsh(np.asarray(pc.covariances))  # ascending
    curv = ev[:, 0] / np.maximum(ev.sum(axis=1), 1e-18)
    nrm = np.asarray(pc.normals)
    # A surface seen by the camera faces it; without a camera, a convex object faces away from its middle.
    toward = (np.asarray(viewpoint, dtype=float) - pts) if viewpoint is not None else (pts - pts.mean(axis=0))
    flip = np.einsum("ij,ij->i", nrm, toward) < 0
    nrm = np.where(flip[:, None], -nrm, nrm)
    return nrm, curv


def split_concave(pts: np.ndarray, settings: SegmentSettings, *, viewpoint: np.ndarray | None = None) -> np.ndarray:
    """Cut one cluster at its concave creases; per point a segment id (0, 1, ...) or -1.

    A model-free cut for objects that touch (Stein et al.'s LCCP idea on smooth regions instead of
    supervoxels): points grow smooth regions through neighbours (within ``2.5 cluster_voxel``) whose
    normals differ by less than ``smooth_angle_deg`` and that are no crease (surface variation below
    ``max_curvature``, and ``crease_rings`` neighbour steps from any point above it); creases and tiny
    regions join their neighbours; then adjacent regions merge unless
    the boundary between them is concave - the normals of their points near it (``patch_radius``) turn
    toward each other by more than ``concave_angle_deg``. Two faces of one box meet at a convex edge, a box
    standing on another or a cup against a bowl at a concave one. ``pts`` is ``(n, 3)`` metres, any frame
    with ``viewpoint`` (the camera centre) in it; normals are oriented toward it.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    n = len(pts)
    if n < 3:
        return np.full(n, -1, dtype=np.int64)
    s = settings
    nrm, curv = _normals(pts, s.normal_radius, viewpoint)
    tree = cKDTree(pts)
    edges = tree.query_pairs(2.5 * s.cluster_voxel, output_type="ndarray")
    if len(edges) == 0:
        return np.zeros(n, dtype=np.int64)
    a, b = edges[:, 0], edges[:, 1]
    # A point grows regions only if no crease is within crease_rings neighbour steps: the widened band keeps
    # a few noisy crease points that fall just under max_curvature from bridging two objects.
    near_crease = curv > s.max_curvature
    for _ in range(s.crease_rings):
        ring = near_crease.copy()
        ring[a[near_crease[b]]] = True
        ring[b[near_crease[a]]] = True
        near_crease = ring
    flat = ~near_crease
    cos_s = np.cos(np.radians(s.smooth_angle_deg))
    smooth = flat[a] & flat[b] & (np.einsum("ij,ij->i", nrm[a], nrm[b]) >= cos_s)

    def components(ea: np.ndarray, eb: np.ndarray) -> np.ndarray:
        g = coo_matrix((np.ones(len(ea)), (ea, eb)), shape=(n, n))
        return connected_components(g, directed=False)[1]

    region = components(a[smooth], b[smooth])
    core = flat.copy()
    # Crease points (and isolated flat ones) take the region of their nearest core point.
    sizes = np.bincount(region)
    core &= sizes[region] > 1
    if not core.any():
        return np.zeros(n, dtype=np.int64)
    ci = np.flatnonzero(core)
    _, j = cKDTree(pts[ci]).query(pts[~core])
    region[~core] = region[ci[j]]
    region = np.unique(region, return_inverse=True)[1].reshape(-1)

    parent = np.arange(region.max() + 1)

    def find(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    ra, rb = region[a], region[b]
    cross = ra != rb
    pair_keys, pair_count = np.unique(np.sort(np.stack([ra[cross], rb[cross]], 1), axis=1), axis=0, return_counts=True)
    sizes = np.bincount(region)
    # Tiny regions (noise, the strip along a crease) join the neighbour they share most edges with.
    small = sizes < s.min_region_points
    best: dict[int, tuple[int, int]] = {}
    for (r1, r2), c in zip(pair_keys.tolist(), pair_count.tolist(), strict=True):
        for x, y in ((r1, r2), (r2, r1)):
            if small[x] and not small[y] and c > best.get(x, (-1, 0))[1]:
                best[x] = (y, c)
    for x, (y, _) in best.items():
        parent[find(x)] = find(y)
    # Adjacent regions merge unless their shared boundary is concave.
    cos_c = np.cos(np.radians(s.concave_angle_deg))
    mid = 0.5 * (pts[a[cross]] + pts[b[cross]])
    mid_keys = np.sort(np.stack([ra[cross], rb[cross]], 1), axis=1)
    for (r1, r2), c in zip(pair_keys.tolist(), pair_count.tolist(), strict=True):
        if small[r1] or small[r2] or c < 3:
            continue
        m = mid[(mid_keys[:, 0] == r1) & (mid_keys[:, 1] == r2)]
        mtree = cKDTree(m)
        patch = []
        for r in (r1, r2):
            idx = np.flatnonzero((region == r) & core)
            if len(idx) == 0:
                idx = np.flatnonzero(region == r)
            d, _ = mtree.query(pts[idx], distance_upper_bound=s.patch_radius)
            near = idx[np.isfinite(d)]
            if len(near) == 0:
                near = idx
            nv = nrm[near].sum(axis=0)
            patch.append((pts[near].mean(axis=0), nv / max(float(np.linalg.norm(nv)), 1e-12)))
        (c1, n1), (c2, n2) = patch
        d12 = c1 - c2
        dist = float(np.linalg.norm(d12))
        concave = dist > 0 and float((n1 - n2) @ d12) / dist < 0 and float(n1 @ n2) < cos_c
        if not concave:
            parent[find(r1)] = find(r2)
    roots = np.array([find(x) for x in range(len(parent))])
    return np.unique(roots[region], return_inverse=True)[1].reshape(-1).astype(np.int64)
