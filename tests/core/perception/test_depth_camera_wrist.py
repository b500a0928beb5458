"""The wrist camera's sensor preset (a RealSense D405-like active stereo camera): its field of view, its
stereo noise at 0.1/0.3/0.5 m, its range, and the Kinect's defaults left as they were."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings, look_at


def _plane() -> trimesh.Trimesh:
    """A 1 mm thin 4 m square slab whose top face is z = 0."""
    m = trimesh.creation.box(extents=[4.0, 4.0, 0.001])
    m.apply_translation([0, 0, -0.0005])
    return m


def _down_at(height: float) -> np.ndarray:
    return look_at([0.0, 0.0, height], [0.0, 0.0, 0.0], up=[1.0, 0.0, 0.0])


def test_the_preset_has_the_d405_field_of_view_and_range() -> None:
    s = KinectSettings.wrist_stereo()
    assert 2 * np.degrees(np.arctan(0.5 * s.width / s.fx)) == pytest.approx(87.0)
    assert 2 * np.degrees(np.arctan(0.5 * s.height / s.fy)) == pytest.approx(58.0)
    assert (s.min_range, s.max_range, s.baseline, s.axial_z0) == (0.07, 0.5, 0.018, 0.0)
    # overrides go through, as for ideal()
    assert KinectSettings.wrist_stereo(max_range=0.4).max_range == 0.4


@pytest.mark.parametrize(("z", "sigma_mm"), [(0.1, 0.1318), (0.3, 1.186), (0.5, 3.295)])
def test_stereo_noise_grows_with_the_square_of_depth(z: float, sigma_mm: float) -> None:
    s = KinectSettings.wrist_stereo()
    # sigma_z = z^2 * 0.08 px / (fx * 18 mm)
    assert s.axial_sigma(z) * 1e3 == pytest.approx(sigma_mm, rel=1e-3)
    assert s.axial_sigma(z) == pytest.approx(z**2 * 0.08 / (s.fx * 0.018))
    # the range limit would clip half the noise at 0.5 m
    noisy = s.model_copy(update=dict(quantize=False, lateral_sigma_px=0.0, edge_dropout=0.0, max_range=1.0))
    frame = DepthCamera(noisy, seed=4).render([(_plane(), np.eye(4))], _down_at(z))
    assert np.nanstd(frame.depth) == pytest.approx(s.axial_sigma(z), rel=0.03)
    assert abs(np.nanmean(frame.depth) - z) < 3 * s.axial_sigma(z) / np.sqrt(np.isfinite(frame.depth).sum())


@pytest.mark.parametrize(("z", "step_mm"), [(0.1, 0.0515), (0.3, 0.463), (0.5, 1.287)])
def test_disparity_steps_are_a_32nd_of_a_pixel(z: float, step_mm: float) -> None:
    s = KinectSettings.wrist_stereo()
    assert z**2 / (s.disparity_subpixel * s.baseline * s.fx) * 1e3 == pytest.approx(step_mm, rel=1e-2)
    frame = DepthCamera(s, seed=5).render([(_plane(), np.eye(4))], _down_at(z))
    d = frame.depth[np.isfinite(frame.depth)]
    steps = s.baseline * s.fx / d * s.disparity_subpixel
    assert np.allclose(steps, np.round(steps), atol=1e-6)


def test_the_plane_fills_the_wide_view_and_nothing_is_seen_out_of_range() -> None:
    s = KinectSettings.wrist_stereo()
    frame = DepthCamera(s, seed=6).render([(_plane(), np.eye(4))], _down_at(0.3))
    assert np.isfinite(frame.depth).mean() > 0.95
    # 87 x 58 deg at 0.3 m: 0.569 x 0.333 m of table (the camera's x is the world's -y here)
    extent = np.ptp(frame.points_world[:, :2], axis=0)
    assert extent[1] == pytest.approx(2 * 0.3 * np.tan(np.radians(43.5)), rel=0.02)
    assert extent[0] == pytest.approx(2 * 0.3 * np.tan(np.radians(29.0)), rel=0.02)
    for z in (0.05, 0.55):
        assert not np.isfinite(DepthCamera(s, seed=6).render([(_plane(), np.eye(4))], _down_at(z)).depth).any()


def test_the_kinect_defaults_are_unchanged() -> None:
    k = KinectSettings()
    assert (k.fx, k.fy, k.min_range, k.max_range) == (525.0, 525.0, 0.4, 4.0)
    assert (k.axial_a, k.axial_b, k.axial_z0, k.baseline, k.disparity_subpixel) == (0.0012, 0.0019, 0.4, 0.075, 8)
