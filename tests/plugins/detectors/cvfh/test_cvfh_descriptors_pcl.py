"""Our VFH / CVFH / CRH against PCL 1.13 on the four reference views of the L-block (tests/data/pcl/README.md).

Tolerances and why:
- normals/curvatures: PCL works in float32 (1e-7 relative), so 0.05 deg and 1e-6.
- VFH: 1e-3 per bin, i.e. not a single point in a different bin (one point is worth 100 / (N - 1) ~ 0.2 .. 0.4).
- CVFH, views 00, 07, 33: same regions, centroids to 1e-6 m (float32 sums), mean normals to 1e-3 rad (PCL
  re-estimates them with its float32 closed-form eigen solver: 2.3e-4 rad seen); each histogram block may differ
  by one point moved to a neighbouring bin (L1 <= 2): a point whose normalised distance to the centroid lies on a
  bin edge can round either way in float32 vs float64 (seen once, view 33, size block).
- CVFH, view 21: region membership differs (the README warns it is where implementations part): PCL finds one
  region, we find the same one plus a 62-point region on the face PCL did not grow. It is not a float-rounding
  effect at the angle threshold (the nearest link is 8.6e-5 rad from it, and flipping any link within 2e-3 rad
  does not reproduce PCL); PCL's float32 closed-form eigen solver for the internal normals and its unsorted FLANN
  radius search (the growing loop skips ``nn_indices[0]`` assuming it is the seed) are the likely causes, and
  neither can be reproduced exactly. The shared region must still agree to 0.5 mm, 0.5 deg and 10 % of the points
  per histogram block.
- CRH: 1e-5 (float32 FFT).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from asmteach.plugins.detectors.cvfh.descriptors import (
    compute_crh,
    compute_cvfh,
    compute_vfh,
    estimate_normals_curvature,
)

BLOCKS = ((0, 45), (45, 90), (90, 135), (135, 180), (180, 308))


def _block_l1(a: np.ndarray, b: np.ndarray) -> list[float]:
    return [float(np.abs(a[s:e] - b[s:e]).sum()) for s, e in BLOCKS]


def test_normals_and_curvatures_match_pcl(pcl_view: Any) -> None:
    normals, curv = estimate_normals_curvature(pcl_view.points, pcl_view.ref["params"]["normal_radius"])
    cos = np.clip(np.einsum("ij,ij->i", normals, pcl_view.normals), -1.0, 1.0)
    assert np.degrees(np.arccos(cos)).max() < 0.05
    np.testing.assert_allclose(curv, pcl_view.curvatures, atol=1e-6)


def test_vfh_matches_pcl_bin_by_bin(pcl_view: Any) -> None:
    hist = compute_vfh(pcl_view.points, pcl_view.normals)
    ref = np.asarray(pcl_view.ref["vfh"])
    assert hist.shape == (308,)
    np.testing.assert_allclose(hist, ref, atol=1e-3)
    # PCL's defaults: size block empty, blocks scaled to 100 / (N - 1) and 100 / N.
    n = len(pcl_view.points)
    assert np.all(hist[135:180] == 0.0)
    assert abs(hist[:45].sum() - 100.0 * n / (n - 1)) < 1e-6
    assert abs(hist[180:].sum() - 100.0) < 1e-6


def test_cvfh_regions_and_bins_match_pcl(view_loader: Any) -> None:
    for name in ("00", "07", "33"):
        view = view_loader(name)
        regions = compute_cvfh(view.points, view.normals, view.curvatures)
        ref = view.ref["descriptors"]["cvfh"]
        assert len(regions) == len(ref), name
        for ours, theirs in zip(regions, ref, strict=True):
            assert ours.smooth
            np.testing.assert_allclose(ours.centroid, theirs["centroid"], atol=1e-6)
            assert np.arccos(min(1.0, float(ours.normal @ np.asarray(theirs["normal"])))) < 1e-3
            hist = np.asarray(theirs["hist"])
            assert max(_block_l1(ours.hist, hist)) <= 2.0, (name, _block_l1(ours.hist, hist))
            # not normalised: every block holds one count per point
            np.testing.assert_allclose([ours.hist[s:e].sum() for s, e in BLOCKS], len(view.points))


def test_cvfh_view21_shares_pcl_region(view_loader: Any) -> None:
    view = view_loader("21")
    regions = compute_cvfh(view.points, view.normals, view.curvatures)
    (theirs,) = view.ref["descriptors"]["cvfh"]
    assert 1 <= len(regions) <= 2
    dist = [np.linalg.norm(r.centroid - np.asarray(theirs["centroid"])) for r in regions]
    ours = regions[int(np.argmin(dist))]
    assert min(dist) < 0.5e-3
    assert np.degrees(np.arccos(min(1.0, float(ours.normal @ np.asarray(theirs["normal"]))))) < 0.5
    assert max(_block_l1(ours.hist, np.asarray(theirs["hist"]))) <= 0.1 * len(view.points)


def test_crh_matches_pcl(pcl_view: Any) -> None:
    desc = pcl_view.ref["descriptors"]
    crh = compute_crh(pcl_view.points, pcl_view.normals, np.asarray(desc["centroid"]))
    assert crh.shape == (90,) and crh[0] == 1.0
    np.testing.assert_allclose(crh, desc["crh"], atol=1e-5)
