"""Clustered Viewpoint Feature Histogram (CVFH), as ``pcl::CVFHEstimation`` (PCL 1.13) computes it.

Steps (all in the camera frame, metres):

1. keep the points whose input curvature is at most ``curvature_threshold`` (flat enough to seed smooth regions);
2. re-estimate their normals with ``internal_normal_radius`` over the kept points only;
3. grow smooth regions: two kept points are linked when they are within ``cluster_tolerance`` and their
   re-estimated normals differ by less than ``eps_angle``; a region is a connected set of links with at least
   ``min_points`` points (PCL's seed-queue growing yields exactly these connected components, in the order of their
   lowest point index);
4. per region, a VFH over *all* points with the region centroid and mean normal as reference, the size block on,
   distances normalised by the largest distance to the centroid, and the viewpoint block about the viewpoint.

With no region, one VFH over all points about the cloud centroid and the (unnormalised) mean input normal is returned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import BaseModel, ConfigDict, Field
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from asmteach.core.errors import UserError
from asmteach.plugins.detectors.cvfh.descriptors.normals import (
    neighbourhood_covariances,
    normals_from_covariances,
    radius_pairs,
)
from asmteach.plugins.detectors.cvfh.descriptors.vfh import check_cloud, vfh_histogram


class CvfhParams(BaseModel):
    """CVFH settings; defaults are the ones the PCL reference histograms were computed with."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    normal_radius: float = Field(0.010, gt=0, description="Radius for the input normals and curvatures, metres.")
    eps_angle: float = Field(0.125, gt=0, description="Max angle between linked normals in a smooth region, radians.")
    curvature_threshold: float = Field(0.03, ge=0, description="Max input curvature of a point that may join a region.")
    cluster_tolerance: float = Field(0.015, gt=0, description="Max distance between linked region points, metres.")
    min_points: int = Field(50, ge=1, description="Min points of a smooth region.")
    internal_normal_radius: float = Field(0.015, gt=0, description="Radius to re-estimate region normals, metres.")
    normalize_bins: bool = Field(False, description="Scale blocks to 100 / (n - 1) per pair instead of 1 per point.")


@dataclass
class CvfhRegion:
    """One CVFH descriptor and the smooth region it is anchored on.

    Attributes:
        hist: ``(308,)`` histogram (f1 | f2 | f3 | centroid distance | viewpoint).
        centroid: ``(3,)`` region centroid, metres, frame of the input points.
        normal: ``(3,)`` unit mean of the region's re-estimated normals. For the fallback (``smooth`` False, where
            PCL reports no normal) the normalised mean input normal.
        indices: ``(k,)`` indices into the input points of the region (all points for the fallback).
        smooth: False when no smooth region existed and the histogram covers the whole cloud.
    """

    hist: NDArray[np.float64]
    centroid: NDArray[np.float64]
    normal: NDArray[np.float64]
    indices: NDArray[np.intp]
    smooth: bool = True


def smooth_regions(
    points: NDArray[np.float64],
    normals: NDArray[np.float64],
    tolerance: float,
    eps_angle: float,
    min_points: int,
    *,
    pairs: NDArray[np.intp] | None = None,
) -> list[NDArray[np.intp]]:
    """Connected smooth regions of a cloud (PCL's ``extractEuclideanClustersSmooth``), vectorised.

    Args:
        points: ``(n, 3)`` points, metres.
        normals: ``(n, 3)`` unit normals (NaN rows never link).
        tolerance: link distance, metres (inclusive).
        eps_angle: link when the angle between normals is below this, radians.
        min_points: smallest region kept.
        pairs: ``(m, 2)`` precomputed :func:`radius_pairs` of ``points`` at ``tolerance`` (computed when None).

    Returns:
        Sorted index arrays of the regions, ordered by their lowest index (PCL's order).
    """
    n = points.shape[0]
    if n == 0:
        return []
    if pairs is None:
        pairs = radius_pairs(points, tolerance)
    if pairs.size:
        dots = np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]])
        # acos(dot) < eps  <=>  dot > cos(eps); NaN normals compare False and so never link.
        pairs = pairs[dots > np.cos(eps_angle)]
    labels = _components(pairs, n)
    sizes = np.bincount(labels)
    regions = [np.flatnonzero(labels == lab) for lab in np.flatnonzero(sizes >= min_points)]
    # PCL's seed loop finds the regions in the order of their lowest index.
    return sorted(regions, key=lambda r: int(r[0]))


def _components(pairs: NDArray[np.intp], n: int) -> NDArray[np.int32]:
    """Connected-component label of each of ``n`` nodes linked by ``pairs`` (labels ordered by lowest member)."""
    # Build the CSR graph by hand: scipy's COO -> CSR conversion sorts every row, which costs more than the search.
    rows = pairs[:, 0].astype(np.uint16 if n <= np.iinfo(np.uint16).max else np.int64)
    order = np.argsort(rows, kind="stable")  # radix sort for 16-bit keys
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(pairs[:, 0], minlength=n), out=indptr[1:])
    graph = csr_matrix((np.ones(len(pairs), dtype=np.int8), pairs[order, 1], indptr), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    return labels


def compute_cvfh(
    points: ArrayLike,
    normals: ArrayLike,
    curvatures: ArrayLike,
    params: CvfhParams | None = None,
    *,
    viewpoint: ArrayLike = (0.0, 0.0, 0.0),
) -> list[CvfhRegion]:
    """CVFH descriptors of one view, one per smooth region.

    Args:
        points: ``(n, 3)`` points, metres, camera frame (PCL always takes the viewpoint at the origin).
        normals: ``(n, 3)`` unit normals facing the viewpoint (e.g. :func:`estimate_normals_curvature` with
            ``params.normal_radius``); points with a NaN normal are left out.
        curvatures: ``(n,)`` surface variation of each point (NaN never joins a region).
        params: settings; ``CvfhParams()`` (PCL's) when None.
        viewpoint: ``(3,)`` camera position in the frame of ``points``, metres. Only for clouds given in another
            frame; the default reproduces PCL.

    Returns:
        The regions in PCL's order, or one whole-cloud descriptor (``smooth`` False) when there is no region.

    Raises:
        UserError: empty cloud, shape mismatch, non-finite points, or no finite normal.
    """
    prm = params if params is not None else CvfhParams()
    p, n, ok = check_cloud(points, normals, "compute_cvfh")
    curv = np.asarray(curvatures, dtype=np.float64)
    if curv.shape != (p.shape[0],):
        raise UserError(f"compute_cvfh: curvatures shape {curv.shape} must be ({p.shape[0]},), one per point")
    vp = np.asarray(viewpoint, dtype=np.float64)
    if not ok.all():
        # Points without a normal take no part; region indices still refer to the caller's points.
        kept = np.flatnonzero(ok)
        sub = compute_cvfh(p[kept], n[kept], curv[kept], prm, viewpoint=vp)
        for region in sub:
            region.indices = kept[region.indices]
        return sub

    flat = np.flatnonzero(curv <= prm.curvature_threshold)
    regions: list[tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]] = []
    if flat.size >= prm.min_points:
        flat_pts = p[flat]
        # PCL re-estimates the normals of the kept points over the kept points only.
        normal_pairs = radius_pairs(flat_pts, prm.internal_normal_radius)
        flat_normals, _ = normals_from_covariances(flat_pts, *neighbourhood_covariances(flat_pts, normal_pairs), vp)
        # Both radii are 15 mm by default: one neighbour search then serves the normals and the region growing.
        same = prm.cluster_tolerance == prm.internal_normal_radius
        link_pairs = normal_pairs if same else radius_pairs(flat_pts, prm.cluster_tolerance)
        for members in smooth_regions(
            flat_pts, flat_normals, prm.cluster_tolerance, prm.eps_angle, prm.min_points, pairs=link_pairs
        ):
            mean_normal = flat_normals[members].mean(axis=0)
            if not np.isfinite(mean_normal).all():  # a lone point without a normal (only when min_points == 1)
                continue
            regions.append((flat[members], flat_pts[members].mean(axis=0), mean_normal / np.linalg.norm(mean_normal)))

    out: list[CvfhRegion] = []
    for idx, centroid, ref_normal in regions:
        hist = _cvfh_hist(p, n, centroid, ref_normal, vp, prm.normalize_bins)
        out.append(CvfhRegion(hist=hist, centroid=centroid, normal=ref_normal, indices=idx))
    if not out:
        centroid = p.mean(axis=0)
        mean_normal = n.mean(axis=0)  # PCL uses the unnormalised mean as the reference normal here
        hist = _cvfh_hist(p, n, centroid, mean_normal, vp, prm.normalize_bins)
        norm = float(np.linalg.norm(mean_normal))
        unit = mean_normal / norm if norm > 0 else mean_normal
        out.append(CvfhRegion(hist=hist, centroid=centroid, normal=unit, indices=np.arange(len(p)), smooth=False))
    return out


def _cvfh_hist(
    p: NDArray[np.float64],
    n: NDArray[np.float64],
    centroid: NDArray[np.float64],
    ref_normal: NDArray[np.float64],
    viewpoint: NDArray[np.float64],
    normalize_bins: bool,
) -> NDArray[np.float64]:
    """One CVFH histogram: VFH of all points about ``centroid``, size block on, distances normalised."""
    to_vp = viewpoint - centroid  # a given centroid is a direction (w = 0) in PCL, so no homogeneous quirk here
    norm = float(np.linalg.norm(to_vp))
    vp_dir = to_vp / norm if norm > 0 else to_vp
    return vfh_histogram(
        p, n, centroid, ref_normal, vp_dir, normalize_bins=normalize_bins, normalize_distances=True, size_component=True
    )
