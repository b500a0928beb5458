"""Hand-checkable clouds for the pair features, VFH, CVFH and normals, and bad input."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from asmteach.core.errors import UserError
from asmteach.plugins.detectors.cvfh.descriptors import (
    CvfhParams,
    compute_crh,
    compute_cvfh,
    compute_vfh,
    crh_roll_candidates,
    estimate_normals_curvature,
    pair_features,
)
from asmteach.plugins.detectors.cvfh.descriptors.normals import neighbourhood_covariances, radius_pairs

import open3d as o3d  # isort: skip  (after asmteach, which loads libusb for open3d)


def _plane(n_side: int = 20, step: float = 0.002, z: float = 0.5) -> np.ndarray:
    """A fronto-parallel square grid centred on the optical axis (even side: no point at the centroid)."""
    g = (np.arange(n_side) - (n_side - 1) / 2) * step
    xx, yy = np.meshgrid(g, g)
    return np.column_stack([xx.ravel(), yy.ravel(), np.full(xx.size, z)])


def test_pair_features_by_hand() -> None:
    # Coplanar points with equal normals: every angle feature is 0.
    f = pair_features([0, 0, 0], [0, 0, 1], [1, 0, 0], [0, 0, 1])
    assert f.valid[0]
    np.testing.assert_allclose([f.f1[0], f.f2[0], f.f3[0], f.f4[0]], [0, 0, 0, 1], atol=1e-12)
    # Target normal tilted 30 deg toward the source: it is the better aligned one, so the pair is swapped;
    # then u = n2, v = +y, w = (-cos, 0, sin) and f1 = atan2(sin 30, cos 30).
    t = np.radians(30.0)
    n2 = [np.sin(t), 0.0, np.cos(t)]
    f = pair_features([0, 0, 0], [0, 0, 1], [1, 0, 0], n2)
    np.testing.assert_allclose([f.f1[0], f.f2[0], f.f3[0], f.f4[0]], [t, 0.0, -0.5, 1.0], atol=1e-12)
    # The ordering rule makes the features independent of the order the pair is given in.
    g = pair_features([1, 0, 0], n2, [0, 0, 0], [0, 0, 1])
    np.testing.assert_allclose([g.f1[0], g.f2[0], g.f3[0], g.f4[0]], [t, 0.0, -0.5, 1.0], atol=1e-12)
    # Coincident points and a normal along the connecting line are rejected, as PCL does.
    bad = pair_features([[0, 0, 0], [0, 0, 0]], [[0, 0, 1], [1, 0, 0]], [[0, 0, 0], [1, 0, 0]], [[0, 0, 1], [1, 0, 0]])
    assert not bad.valid.any()


def test_vfh_of_a_plane_by_hand() -> None:
    pts = _plane()
    nrm = np.tile([0.0, 0.0, -1.0], (len(pts), 1))
    n = len(pts)
    hist = compute_vfh(pts, nrm)
    # f1 = f2 = f3 = 0 for every point; PCL bins all three over [-pi, pi]: floor(45 * pi / 2pi) = 22.
    for k in range(3):
        block = hist[45 * k : 45 * (k + 1)]
        assert block[22] == pytest.approx(100.0 * n / (n - 1))
        assert np.count_nonzero(block) == 1
    assert np.all(hist[135:180] == 0.0)
    # Viewpoint block with PCL's homogeneous quirk: cos = 0.5 / sqrt(0.5^2 + 1) -> floor(128 * (cos + 1) / 2) = 92.
    assert hist[180 + 92] == pytest.approx(100.0)
    # Size block in centimetres when asked (grid half-diagonal 2.7 cm -> bins 0..3).
    sized = compute_vfh(pts, nrm, size_component=True)
    r = np.linalg.norm(pts - pts.mean(axis=0), axis=1)
    expected = np.bincount(np.floor(100 * r + 0.5).astype(int), minlength=45) * 100.0 / (n - 1)
    np.testing.assert_allclose(sized[135:180], expected, atol=1e-9)


def test_cvfh_of_a_plane_is_one_region() -> None:
    pts = _plane()
    normals, curv = estimate_normals_curvature(pts, 0.010)
    np.testing.assert_allclose(normals, np.tile([0.0, 0.0, -1.0], (len(pts), 1)), atol=1e-9)
    assert np.all(curv < 1e-9)
    (region,) = compute_cvfh(pts, normals, curv)
    n = len(pts)
    assert region.smooth and len(region.indices) == n
    np.testing.assert_allclose(region.centroid, pts.mean(axis=0), atol=1e-12)
    np.testing.assert_allclose(region.normal, [0.0, 0.0, -1.0], atol=1e-9)
    for k in range(3):
        assert region.hist[45 * k + 22] == n
    # Size block normalised by the largest distance: the four corners are at the maximum and land in bin 44.
    assert region.hist[135:180].sum() == n and region.hist[135 + 44] >= 4
    # The region centroid is given, so no homogeneous quirk: every normal faces the camera, bin 127.
    assert region.hist[180 + 127] == n


def test_cvfh_of_a_cube_corner_has_three_face_regions() -> None:
    a, step = 0.06, 0.002
    g = np.arange(step / 2, a, step)
    u, v = (m.ravel() for m in np.meshgrid(g, g))
    zero = np.zeros_like(u)
    faces = [np.column_stack(c) for c in ((zero, u, v), (u, zero, v), (u, v, zero))]
    rot = Rotation.align_vectors([[0.0, 0.0, 1.0]], [np.ones(3) / np.sqrt(3)])[0]  # corner points at the camera
    pts = rot.apply(np.vstack(faces)) + np.array([0.0, 0.0, 0.5])
    normals, curv = estimate_normals_curvature(pts, 0.010)
    regions = compute_cvfh(pts, normals, curv)
    assert len(regions) == 3
    expected = rot.apply(-np.eye(3))  # outward normals of the three faces, all facing the camera
    for region in regions:
        best = np.max(expected @ region.normal)
        assert np.degrees(np.arccos(min(1.0, best))) < 2.0
        assert region.hist[135:180].sum() == len(pts)


def test_cvfh_falls_back_to_one_vfh_without_smooth_region() -> None:
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(200, 3)) * 0.01 + [0.0, 0.0, 0.6]
    normals = -pts / np.linalg.norm(pts, axis=1, keepdims=True)
    (region,) = compute_cvfh(pts, normals, np.full(len(pts), 0.2))  # nothing flat enough
    assert not region.smooth
    np.testing.assert_array_equal(region.indices, np.arange(len(pts)))
    np.testing.assert_allclose(region.centroid, pts.mean(axis=0))
    assert region.hist[180:].sum() == len(pts)


def test_normals_match_open3d_covariances_and_flag_isolated_points() -> None:
    rng = np.random.default_rng(0)
    pts = np.vstack([rng.uniform(-0.02, 0.02, size=(300, 3)) * [1, 1, 0.1] + [0, 0, 0.7], [[0.5, 0.5, 1.0]]])
    cov, counts = neighbourhood_covariances(pts, radius_pairs(pts, 0.008))
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    cloud.estimate_covariances(o3d.geometry.KDTreeSearchParamRadius(0.008))
    o3d_cov = np.asarray(cloud.covariances)
    ok = counts >= 3  # Open3D writes the identity below 3 neighbours
    np.testing.assert_allclose(cov[ok], o3d_cov[ok], atol=1e-15)
    normals, curv = estimate_normals_curvature(pts, 0.008)
    assert np.isnan(normals[-1]).all() and np.isnan(curv[-1])
    assert np.all(normals[:-1, 2] < 0)  # oriented toward the camera at the origin


def test_points_without_normals_are_left_out() -> None:
    pts = _plane()
    normals, curv = estimate_normals_curvature(pts, 0.010)
    far = np.vstack([pts, [[0.3, 0.3, 0.9]]])  # an isolated point: NaN normal and curvature
    far_normals, far_curv = estimate_normals_curvature(far, 0.010)
    assert np.isnan(far_normals[-1]).all()
    (with_nan,) = compute_cvfh(far, far_normals, far_curv)
    (clean,) = compute_cvfh(pts, normals, curv)
    np.testing.assert_array_equal(with_nan.indices, clean.indices)
    np.testing.assert_allclose(with_nan.hist, clean.hist)
    np.testing.assert_allclose(compute_vfh(far, far_normals), compute_vfh(pts, normals))
    tilted = normals + np.array([0.3, 0.1, 0.0])  # a plane facing the camera has no roll; give the normals some
    far_tilted = np.vstack([tilted, far_normals[-1:]])
    c = pts.mean(axis=0)
    np.testing.assert_allclose(compute_crh(far, far_tilted, c), compute_crh(pts, tilted, c))


def test_bad_input_raises_user_error() -> None:
    pts = _plane()
    nrm = np.tile([0.0, 0.0, -1.0], (len(pts), 1))
    with pytest.raises(UserError, match="normals shape"):
        compute_vfh(pts, nrm[:-1])
    with pytest.raises(UserError, match="non-empty"):
        compute_vfh(np.zeros((0, 3)), np.zeros((0, 3)))
    bad = pts.copy()
    bad[3, 0] = np.nan
    with pytest.raises(UserError, match="NaN"):
        compute_cvfh(bad, nrm, np.zeros(len(pts)))
    with pytest.raises(UserError, match="no point has a finite normal"):
        compute_vfh(pts, np.full_like(nrm, np.nan))
    with pytest.raises(UserError, match="curvatures"):
        compute_cvfh(pts, nrm, np.zeros(3))
    with pytest.raises(UserError, match="centroid"):
        compute_crh(pts, nrm, [0.0, 0.0, 0.0])
    with pytest.raises(UserError, match="parallel"):
        compute_crh(pts, nrm, [0.0, 0.0, 0.5])
    with pytest.raises(UserError, match="CRH"):
        crh_roll_candidates(np.zeros(89), np.zeros(90))
    with pytest.raises(UserError, match="radius"):
        estimate_normals_curvature(pts, 0.0)
    with pytest.raises(ValueError, match="eps_angle"):
        CvfhParams(eps_angle=-0.1)
