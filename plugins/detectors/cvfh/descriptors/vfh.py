"""Viewpoint Feature Histogram (VFH), 308 bins, as ``pcl::VFHEstimation`` (PCL 1.13) computes it.

Layout: 45 bins f1 | 45 bins f2 | 45 bins f3 | 45 bins centroid distance (the "size" block) | 128 bins viewpoint.
As in PCL 1.13, f1, f2 and f3 are all binned as angles over ``[-pi, pi]``, so the cosines f2 and f3 only reach the
middle bins 15..29 of their blocks (a PCL quirk kept for bin-by-bin compatibility).
The first four blocks histogram the pair features (:mod:`.pairs`) between a reference point (the centroid, with a
reference normal) and every point; the viewpoint block histograms the cosine between each point normal and the
direction from the centroid to the viewpoint.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from asmteach.core.errors import UserError
from asmteach.plugins.detectors.cvfh.descriptors.pairs import pair_features

N_BINS_F = 45
N_BINS_VP = 128
VFH_SIZE = 4 * N_BINS_F + N_BINS_VP  # 308


def check_cloud(
    points: ArrayLike, normals: ArrayLike, what: str
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Validate a cloud with normals.

    Returns:
        ``points`` and ``normals`` as ``(n, 3)`` float arrays and the ``(n,)`` mask of rows with a finite normal
        (:func:`estimate_normals_curvature` gives NaN to points with fewer than 3 neighbours; descriptors skip them).

    Raises:
        UserError: wrong shapes, an empty cloud, non-finite points, or no finite normal at all.
    """
    p = np.asarray(points, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] == 0:
        raise UserError(f"{what}: points must be a non-empty (n, 3) array in metres, got shape {p.shape}")
    if n.shape != p.shape:
        raise UserError(f"{what}: normals shape {n.shape} differs from points shape {p.shape}; pass one per point")
    if not np.isfinite(p).all():
        raise UserError(f"{what}: points contain NaN/inf; drop invalid points before computing descriptors")
    ok = np.isfinite(n).all(axis=1)
    if not ok.any():
        raise UserError(f"{what}: no point has a finite normal; estimate normals with a larger radius")
    return p, n, ok


def _bin(values: NDArray[np.float64], n_bins: int) -> NDArray[np.intp]:
    """Floor ``values`` (already scaled to ``[0, n_bins]``) to bin indices, clamped as PCL clamps them."""
    return np.clip(np.floor(values), 0, n_bins - 1).astype(np.intp)


def vfh_histogram(
    points: NDArray[np.float64],
    normals: NDArray[np.float64],
    centroid: NDArray[np.float64],
    ref_normal: NDArray[np.float64],
    viewpoint_dir: NDArray[np.float64],
    *,
    normalize_bins: bool,
    normalize_distances: bool,
    size_component: bool,
) -> NDArray[np.float64]:
    """VFH of all ``points`` about a given reference point, the core of both VFH and CVFH.

    Args:
        points: ``(n, 3)`` points, metres.
        normals: ``(n, 3)`` unit normals.
        centroid: ``(3,)`` reference point, metres.
        ref_normal: ``(3,)`` reference normal (used as given: PCL's plain VFH passes the unnormalised mean normal).
        viewpoint_dir: ``(3,)`` unit-or-shorter vector from the centroid toward the viewpoint; the viewpoint bin of a
            point is ``floor(128 * (n . viewpoint_dir + 1) / 2)``.
        normalize_bins: PCL ``setNormalizeBins``: the first four blocks add ``100 / (n - 1)`` per pair and the
            viewpoint block ``100 / n`` per point; otherwise every point adds 1.
        normalize_distances: bin the distance to the centroid over ``[0, max distance]`` (45 bins) rather than in
            centimetres (``round(100 * d)``, clamped to bin 44).
        size_component: fill the distance block (otherwise it stays zero).

    Returns:
        ``(308,)`` histogram.
    """
    n = points.shape[0]
    pf = pair_features(centroid, ref_normal, points, normals)
    ok = pf.valid
    hist = np.zeros(VFH_SIZE)
    incr = 100.0 / (n - 1) if (normalize_bins and n > 1) else 1.0
    # PCL 1.13 bins all three angular features over [-pi, pi] (one loop for f1..f3), although f2 and f3 are
    # cosines in [-1, 1]: they land in bins 15..29 only. Kept so our histograms are comparable with PCL's.
    for k, f in enumerate((pf.f1, pf.f2, pf.f3)):
        b = _bin(N_BINS_F * (f[ok] + np.pi) / (2.0 * np.pi), N_BINS_F)
        hist[k * N_BINS_F : (k + 1) * N_BINS_F] = np.bincount(b, minlength=N_BINS_F) * incr
    if size_component:
        if normalize_distances:
            d_max = float(np.max(np.linalg.norm(points - centroid, axis=1)))
            scaled = N_BINS_F * pf.f4[ok] / d_max if d_max > 0 else np.zeros(int(ok.sum()))
            d_bins = _bin(scaled, N_BINS_F)
        else:
            # PCL rounds the raw distance in centimetres (pcl_round = floor(x + 0.5) for x >= 0).
            d_bins = _bin(np.floor(pf.f4[ok] * 100.0 + 0.5), N_BINS_F)
        hist[3 * N_BINS_F : 4 * N_BINS_F] = np.bincount(d_bins, minlength=N_BINS_F) * incr
    vp_incr = 100.0 / n if normalize_bins else 1.0
    alpha = (normals @ viewpoint_dir + 1.0) * 0.5
    hist[4 * N_BINS_F :] = np.bincount(_bin(alpha * N_BINS_VP, N_BINS_VP), minlength=N_BINS_VP) * vp_incr
    return hist


def compute_vfh(
    points: ArrayLike,
    normals: ArrayLike,
    viewpoint: ArrayLike = (0.0, 0.0, 0.0),
    *,
    normalize_distances: bool = False,
    size_component: bool = False,
) -> NDArray[np.float64]:
    """Plain VFH of a whole cloud with ``pcl::VFHEstimation``'s defaults.

    The reference point is the centroid with the (unnormalised) mean normal; bins are normalised (``100 / (n - 1)``
    per pair, ``100 / n`` per point in the viewpoint block); the size block is zero unless ``size_component``.

    PCL quirk kept on purpose: its centroid is a homogeneous 4-vector with ``w = 1`` while the viewpoint has
    ``w = 0``, so the "unit" viewpoint direction it normalises is ``(v - c, -1)``; the viewpoint cosine is thus
    ``n . (v - c) / sqrt(|v - c|^2 + 1)`` (distances in metres), which compresses the viewpoint block toward its middle.

    Args:
        points: ``(n, 3)`` points, metres, in the frame of ``viewpoint`` (camera frame: viewpoint at the origin).
        normals: ``(n, 3)`` unit normals, oriented toward the viewpoint.
        viewpoint: ``(3,)`` viewpoint, metres.
        normalize_distances: see :func:`vfh_histogram`.
        size_component: see :func:`vfh_histogram`.

    Returns:
        ``(308,)`` float histogram.

    Points whose normal is NaN are left out.

    Raises:
        UserError: empty cloud, shape mismatch, non-finite points, or no finite normal.
    """
    p, n, ok = check_cloud(points, normals, "compute_vfh")
    p, n = p[ok], n[ok]  # points without a normal are left out, as from the cloud
    centroid = p.mean(axis=0)
    ref_normal = n.mean(axis=0)
    to_vp = np.append(np.asarray(viewpoint, dtype=np.float64) - centroid, -1.0)
    vp_dir = (to_vp / np.linalg.norm(to_vp))[:3]
    return vfh_histogram(
        p,
        n,
        centroid,
        ref_normal,
        vp_dir,
        normalize_bins=True,
        normalize_distances=normalize_distances,
        size_component=size_component,
    )
