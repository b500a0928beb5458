"""The virtual Kinect: geometry of an ideal camera, each term of the noise model, and the camera centre a written
cloud carries."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from asmteach.core import geometry
from asmteach.core.clouds import read_cloud
from asmteach.core.errors import UserError
from asmteach.core.perception.depth_camera import (
    DepthCamera,
    KinectSettings,
    look_at,
    write_cloud_ply,
)

import open3d as o3d  # isort: skip


def _plane(size: float = 4.0) -> trimesh.Trimesh:
    """A 1 mm thin square slab whose top face is z = 0."""
    m = trimesh.creation.box(extents=[size, size, 0.001])
    m.apply_translation([0, 0, -0.0005])
    return m


def _down_at(height: float) -> np.ndarray:
    return look_at([0.0, 0.0, height], [0.0, 0.0, 0.0], up=[1.0, 0.0, 0.0])


def test_look_at_frame_is_opencv_and_proper() -> None:
    T = look_at([1.0, 2.0, 3.0], [1.5, 2.0, 0.0])
    R = T[:3, :3]
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-12) and np.isclose(np.linalg.det(R), 1.0)
    z = np.array([0.5, 0.0, -3.0]) / np.linalg.norm([0.5, 0.0, -3.0])
    assert np.allclose(R[:, 2], z)
    # Image "down" (camera y) points away from world up.
    assert R[:, 1] @ np.array([0.0, 0.0, 1.0]) < 0
    with pytest.raises(ValueError, match="parallel"):
        look_at([0, 0, 1], [0, 0, 0], up=[0, 0, 1])
    with pytest.raises(ValueError, match="coincide"):
        look_at([0, 0, 1], [0, 0, 1])


def test_ideal_camera_sees_a_plane_at_its_distance() -> None:
    s = KinectSettings.ideal()
    frame = DepthCamera(s).render([(_plane(), np.eye(4))], _down_at(0.9))
    assert frame.depth.shape == (480, 640)
    assert np.all(np.isfinite(frame.depth))
    assert np.allclose(frame.depth, 0.9, atol=1e-6)
    assert np.allclose(frame.points_world[:, 2], 0.0, atol=1e-6)
    # Back-projection agrees with the pinhole model: project again, land on the pixel.
    uvw = frame.points_cam @ s.K.T
    uv = uvw[:, :2] / uvw[:, 2:]
    assert np.allclose(uv[:, 0], frame.pixels[:, 1], atol=1e-6)
    assert np.allclose(uv[:, 1], frame.pixels[:, 0], atol=1e-6)
    # Width of the footprint: 640 px at fx = 525 and 0.9 m.
    assert np.ptp(frame.points_cam[:, 0]) == pytest.approx(639 * 0.9 / 525, rel=1e-6)


def test_mesh_pose_labels_and_world_frame() -> None:
    box = trimesh.creation.box(extents=[0.1, 0.1, 0.05])
    T_box = geometry.from_rpy(0, 0, 0.3, t=[0.05, -0.02, 0.025])
    frame = DepthCamera(KinectSettings.ideal()).render([(_plane(), np.eye(4)), (box, T_box)], _down_at(0.8))
    on_box = frame.labels == 1
    assert 1000 < on_box.sum() < 20000
    # The box top is 5 cm above the plane, at its world pose.
    top = frame.points_world[on_box]
    assert np.allclose(top[:, 2], 0.05, atol=1e-5)
    local = geometry.transform_points(geometry.invert(T_box), top)
    assert np.all(np.abs(local[:, :2]) <= 0.05 + 1e-5)
    assert np.allclose(frame.points_world[~on_box][:, 2], 0.0, atol=1e-5)


def test_axial_noise_follows_sigma_of_z() -> None:
    s = KinectSettings.ideal(axial_noise=True)
    frame = DepthCamera(s, seed=1).render([(_plane(), np.eye(4))], _down_at(1.4))
    expected = 0.0012 + 0.0019 * (1.4 - 0.4) ** 2
    assert s.axial_sigma(1.4) == pytest.approx(expected)
    assert np.nanstd(frame.depth) == pytest.approx(expected, rel=0.03)
    assert abs(np.nanmean(frame.depth) - 1.4) < 1e-4


def test_depth_is_quantised_in_disparity_steps() -> None:
    s = KinectSettings.ideal(axial_noise=True, quantize=True)
    frame = DepthCamera(s, seed=2).render([(_plane(), np.eye(4))], _down_at(1.0))
    disparity = s.baseline * s.fx / frame.depth[np.isfinite(frame.depth)]
    steps = disparity * s.disparity_subpixel
    assert np.allclose(steps, np.round(steps), atol=1e-6)
    levels = np.unique(np.round(frame.depth, 9))
    assert 3 <= len(levels) < 40
    # Step between neighbouring levels near 1 m: z^2 / (8 b f) = 3.2 mm.
    gaps = np.diff(levels)
    assert np.median(gaps) == pytest.approx(1.0 / (8 * s.baseline * s.fx), rel=0.1)


def test_grazing_surfaces_give_no_return() -> None:
    s = KinectSettings.ideal(grazing_start_deg=70.0, grazing_end_deg=85.0)
    cam = DepthCamera(s, seed=0)
    # The plane tilted so the view ray meets it at about 88 deg: nothing comes back.
    tilt = geometry.from_rpy(np.radians(88.0), 0.0, 0.0)
    steep = cam.render([(_plane(10.0), tilt)], _down_at(1.0))
    assert np.isfinite(steep.depth).mean() < 0.02
    flat = cam.render([(_plane(10.0), np.eye(4))], _down_at(1.0))
    assert np.isfinite(flat.depth).mean() > 0.99


def test_depth_edges_lose_returns_and_seed_repeats() -> None:
    box = trimesh.creation.box(extents=[0.1, 0.1, 0.1])
    T_box = geometry.from_rotation(np.eye(3), [0.0, 0.0, 0.05])
    scene = [(_plane(), np.eye(4)), (box, T_box)]
    s = KinectSettings.ideal(edge_dropout=1.0, edge_jump=0.01)
    holes = ~np.isfinite(DepthCamera(s).render(scene, _down_at(0.8)).depth)
    ideal = DepthCamera(KinectSettings.ideal()).render(scene, _down_at(0.8))
    assert not (~np.isfinite(ideal.depth)).any()
    # Dropouts form a thin outline around the box top: 4 sides of ~70 px, 2 px wide.
    assert 200 < holes.sum() < 1200
    rows, cols = np.nonzero(holes)
    assert abs(rows.mean() - 239.5) < 3 and abs(cols.mean() - 319.5) < 3

    noisy = KinectSettings()
    a = DepthCamera(noisy, seed=5).render(scene, _down_at(0.8)).depth
    b = DepthCamera(noisy, seed=5).render(scene, _down_at(0.8)).depth
    c = DepthCamera(noisy, seed=6).render(scene, _down_at(0.8)).depth
    assert np.array_equal(np.isnan(a), np.isnan(b)) and np.allclose(a[~np.isnan(a)], b[~np.isnan(b)])
    assert not np.array_equal(np.nan_to_num(a), np.nan_to_num(c))


def test_lateral_noise_blurs_edges_only() -> None:
    box = trimesh.creation.box(extents=[0.1, 0.1, 0.1])
    T_box = geometry.from_rotation(np.eye(3), [0.0, 0.0, 0.05])
    s = KinectSettings.ideal(lateral_sigma_px=1.0)
    frame = DepthCamera(s, seed=3).render([(_plane(), np.eye(4)), (box, T_box)], _down_at(0.8))
    ideal = DepthCamera(KinectSettings.ideal()).render([(_plane(), np.eye(4)), (box, T_box)], _down_at(0.8))
    changed = np.abs(frame.depth - ideal.depth) > 1e-6
    # Flat regions keep their depth; pixels near the box outline swap between top and floor.
    assert 50 < changed.sum() < 2000
    assert np.all(np.isclose(frame.depth[changed], 0.7, atol=1e-5) | np.isclose(frame.depth[changed], 0.8, atol=1e-5))


def _eye(path: Path) -> np.ndarray | None:
    """The camera centre the cloud reader takes from the file's header, else None."""
    T = read_cloud(path).T_data_sensor
    return None if T is None else np.asarray(T)[:3, 3]


def test_written_ply_carries_the_camera_centre(tmp_path: Path) -> None:
    eye = np.array([1.05, -0.02, 0.75])
    frame = DepthCamera(KinectSettings.ideal()).render([(_plane(), np.eye(4))], look_at(eye, [0.45, 0.0, 0.0]))
    path = frame.write_ply(tmp_path / "scene.ply")
    assert np.array_equal(_eye(path), eye)  # repr of the floats: exact round trip
    # Any PLY reader gets the points (float32, world frame).
    pts = np.asarray(o3d.io.read_point_cloud(str(path)).points)
    assert pts.shape == frame.points_world.shape and np.allclose(pts, frame.points_world, atol=1e-6)
    # Files that say nothing: a PLY without the comment, a PCD with PCL's default VIEWPOINT, another suffix.
    write_cloud_ply(tmp_path / "bare.ply", pts[:10])
    o3d.io.write_point_cloud(str(tmp_path / "bare.pcd"), o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts[:10])))
    for name in ("bare.ply", "bare.pcd"):
        assert _eye(tmp_path / name) is None, name
    bad = tmp_path / "bad.ply"
    bad.write_bytes(b"ply\nformat ascii 1.0\ncomment viewpoint 1 nan\nelement vertex 0\nend_header\n")
    with pytest.raises(UserError, match="finite numbers"):
        _eye(bad)
