"""The numpy projection against cv2.projectPoints, its Jacobians, and the joint adjustment built on them."""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np
import pytest

from asmteach.core import geometry
from asmteach.plugins.detectors.aruco.joint import CornerSet, _evaluate, adjust, frame_rms, pack_pose
from asmteach.plugins.detectors.aruco.projection import (
    dist14,
    project_camera_points,
    rotation_matrices,
    skew,
    so3_left_jacobian,
)

K = np.array([[905.0, 0.0, 641.5], [0.0, 910.0, 358.25], [0.0, 0.0, 1.0]])
DISTS = {
    "none": [0.0] * 5,
    "4": [0.08, -0.21, 0.0012, -0.0018],
    "5": [0.08, -0.21, 0.0012, -0.0018, 0.06],
    "8": [0.08, -0.21, 0.0012, -0.0018, 0.06, 0.02, -0.015, 0.03],
    "12": [0.08, -0.21, 0.0012, -0.0018, 0.06, 0.02, -0.015, 0.03, 0.0011, -0.0021, 0.0031, 0.0007],
    "14": [0.08, -0.21, 0.0012, -0.0018, 0.06, 0.02, -0.015, 0.03, 0.0011, -0.0021, 0.0031, 0.0007, 0.02, -0.03],
}


def _central_difference(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """``(len(f(x)), len(x))`` Jacobian of ``f`` by central differences."""
    cols = [(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(len(x))]
    return np.stack(cols, axis=1)


def _points(n: int = 60, seed: int = 0) -> np.ndarray:
    """Camera-frame points in a C615-like field of view at 0.3-0.8 m."""
    rng = np.random.default_rng(seed)
    return rng.uniform([-0.3, -0.18, 0.3], [0.3, 0.18, 0.8], (n, 3))


def test_projection_known_values_pinhole() -> None:
    uv, _ = project_camera_points(np.array([[0.1, -0.05, 0.5], [0.0, 0.0, 2.0]]), K, [0.0] * 5)
    np.testing.assert_allclose(uv, [[905.0 * 0.2 + 641.5, 910.0 * -0.1 + 358.25], [641.5, 358.25]], atol=1e-12)


def test_projection_known_value_radial() -> None:
    # x' = 0.2, y' = 0 -> r2 = 0.04; radial = 1 + 0.1 * 0.04 = 1.004; x'' = 0.2008.
    uv, _ = project_camera_points(np.array([[0.1, 0.0, 0.5]]), K, [0.1, 0.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(uv, [[905.0 * 0.2008 + 641.5, 358.25]], atol=1e-12)


@pytest.mark.parametrize("name", sorted(DISTS))
def test_projection_matches_opencv(name: str) -> None:
    dist = np.array(DISTS[name])
    P = _points()
    ref, _ = cv2.projectPoints(P, np.zeros(3), np.zeros(3), K, dist)
    uv, _ = project_camera_points(P, K, dist)
    np.testing.assert_allclose(uv, ref.reshape(-1, 2), rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", sorted(DISTS))
def test_point_jacobian_matches_opencv_and_finite_differences(name: str) -> None:
    dist = np.array(DISTS[name])
    P = _points(20, seed=1)
    # At the identity pose OpenCV's d(pixel)/d(tvec) is d(pixel)/d(point).
    _, J_cv = cv2.projectPoints(P, np.zeros(3), np.zeros(3), K, dist)
    _, J = project_camera_points(P, K, dist, jacobian=True)
    assert J is not None
    np.testing.assert_allclose(J, J_cv[:, 3:6].reshape(-1, 2, 3), rtol=1e-9, atol=1e-6)
    for i in range(3):
        J_fd = _central_difference(lambda p: project_camera_points(p.reshape(1, 3), K, dist)[0].ravel(), P[i])
        np.testing.assert_allclose(J[i], J_fd, rtol=1e-6, atol=1e-3)


@pytest.mark.parametrize("name", ["none", "14"])
def test_pose_jacobian_matches_opencv(name: str) -> None:
    """d(pixel)/d(rvec) = J_point @ (-[R p]x J_l(rvec)), as OpenCV's projectPoints reports it."""
    dist = np.array(DISTS[name])
    P = _points(30, seed=2) - [0.0, 0.0, 0.5]
    for rvec in (np.array([0.3, -0.2, 0.5]), np.array([2.9, 0.4, -0.3]), np.array([1e-7, 0.0, -2e-7])):
        tvec = np.array([0.01, -0.02, 0.6])
        ref, J_cv = cv2.projectPoints(P, rvec, tvec, K, dist)
        R = rotation_matrices(rvec[None])[0]
        uv, J = project_camera_points(P @ R.T + tvec, K, dist, jacobian=True)
        assert J is not None
        J_r = J @ (-skew(P @ R.T) @ so3_left_jacobian(rvec[None])[0])
        np.testing.assert_allclose(uv, ref.reshape(-1, 2), atol=1e-9)
        np.testing.assert_allclose(J_r, J_cv[:, :3].reshape(-1, 2, 3), rtol=1e-7, atol=1e-5)


def test_dist14_rejects_bad_length() -> None:
    with pytest.raises(ValueError, match="4, 5, 8, 12 or 14"):
        dist14([0.1, 0.2, 0.3])


# ----------------------------------------------------------------- joint adjustment
T_A_B = geometry.from_rpy(0.1, -0.2, 0.3, [0.01, 0.02, 0.05])


def _scene(n_frames: int = 6, seed: int = 3) -> tuple[list[np.ndarray], list[tuple], np.ndarray]:
    """Frames of two 4-corner-square pairs per part, noise-free corners; returns (T_cam_A, data, dist)."""
    rng = np.random.default_rng(seed)
    sq = np.array([[-0.01, 0.01, 0.0], [0.01, 0.01, 0.0], [0.01, -0.01, 0.0], [-0.01, -0.01, 0.0]])
    obj_a = np.concatenate(
        [sq + np.array([0.0, 0.0, 0.02]), sq @ geometry.from_rpy(0.3, 0, 0)[:3, :3].T + np.array([0.03, 0, 0])]
    )
    obj_b = np.concatenate([sq + np.array([0.0, 0.0, 0.03]), sq + np.array([0.0, 0.025, 0.03])])
    dist = np.array(DISTS["5"])
    poses, data = [], []
    for _ in range(n_frames):
        T = geometry.from_rotvec(rng.normal(0, 0.3, 3) + np.array([np.pi, 0, 0]), [*rng.uniform(-0.05, 0.05, 2), 0.45])
        img_a = project_camera_points(geometry.transform_points(T, obj_a), K, dist)[0]
        img_b = project_camera_points(geometry.transform_points(T @ T_A_B, obj_b), K, dist)[0]
        poses.append(T)
        data.append((obj_a, img_a, obj_b, img_b))
    return poses, data, dist


def test_joint_jacobian_matches_finite_differences() -> None:
    poses, data, dist = _scene(3)
    cs = CornerSet.build(data)
    x = np.concatenate([pack_pose(T_A_B)] + [pack_pose(T) for T in poses]) + 0.01
    _, J = _evaluate(x, cs, K, dist, jacobian=True)
    assert J is not None
    J_fd = _central_difference(lambda x: _evaluate(x, cs, K, dist, jacobian=False)[0], x)
    np.testing.assert_allclose(J.toarray(), J_fd, rtol=1e-5, atol=1e-3)


@pytest.mark.parametrize("dense_max_unknowns", [400, 0])
def test_joint_adjustment_recovers_truth_from_perturbed_start(dense_max_unknowns: int) -> None:
    poses, data, dist = _scene()
    cs = CornerSet.build(data)
    rng = np.random.default_rng(7)
    start_ab = T_A_B @ geometry.from_rpy(*np.radians([1.0, -0.7, 0.5]), [0.002, -0.001, 0.0015])
    starts = [T @ geometry.from_rpy(*rng.normal(0, 0.01, 3), rng.normal(0, 0.002, 3)) for T in poses]
    assert np.max(frame_rms(cs, start_ab, starts, K, dist)) > 2.0
    T, fitted, nfev = adjust(cs, start_ab, starts, K, dist, dense_max_unknowns=dense_max_unknowns)
    assert nfev > 0
    assert geometry.translation_distance(T, T_A_B) < 1e-7
    assert geometry.rotation_distance(T, T_A_B) < 1e-7
    np.testing.assert_allclose(frame_rms(cs, T, fitted, K, dist), 0.0, atol=1e-5)


def test_joint_adjustment_downweights_an_outlier_corner() -> None:
    poses, data, dist = _scene()
    obj_a, img_a, obj_b, img_b = data[2]
    img_b = img_b.copy()
    img_b[1] += [15.0, -10.0]  # one corner pulled by a shadow or a finger
    data[2] = (obj_a, img_a, obj_b, img_b)
    cs = CornerSet.build(data)
    T, fitted, _ = adjust(cs, T_A_B, poses, K, dist)
    # Plain least squares moves T_A_B by 0.66 mm here (the 18 px error spread over all unknowns); Huber by 0.024 mm.
    assert geometry.translation_distance(T, T_A_B) < 5e-5
    per_frame = frame_rms(cs, T, fitted, K, dist)
    assert per_frame[2] > 3.0 and np.all(np.delete(per_frame, 2) < 0.5)


def test_corner_set_subset_renumbers_and_repeats_frames() -> None:
    _, data, _ = _scene(3)
    cs = CornerSet.build(data)
    sub = cs.subset([2, 0, 2])
    assert sub.n_frames == 3 and len(sub.obj) == 3 * 16
    np.testing.assert_array_equal(np.bincount(sub.frame), [16, 16, 16])
    np.testing.assert_allclose(sub.img[sub.frame == 1], cs.img[cs.frame == 0])
    np.testing.assert_allclose(sub.obj[sub.frame == 2], cs.obj[cs.frame == 2])
    np.testing.assert_array_equal(sub.is_b[sub.frame == 0], np.repeat([False, True], 8))


def test_frame_rms_matches_opencv() -> None:
    poses, data, dist = _scene(3)
    data = [(oa, ia + 0.3, ob, ib - 0.2) for oa, ia, ob, ib in data]
    cs = CornerSet.build(data)
    got = frame_rms(cs, T_A_B, poses, K, dist)
    for k, (oa, ia, ob, ib) in enumerate(data):
        e = []
        for obj, img, T in ((oa, ia, poses[k]), (ob, ib, poses[k] @ T_A_B)):
            rvec = cv2.Rodrigues(np.ascontiguousarray(T[:3, :3]))[0]
            e.append(cv2.projectPoints(obj, rvec, T[:3, 3], K, dist)[0].reshape(-1, 2) - img)
        assert got[k] == pytest.approx(np.sqrt(np.mean(np.sum(np.concatenate(e) ** 2, axis=1))), abs=1e-9)
