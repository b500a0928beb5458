import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from asmteach.core import geometry as g


def test_rpy_round_trip_matches_urdf_convention():
    T = g.from_rpy(0.1, -0.2, 0.3, t=[1, 2, 3])
    Rz, Ry, Rx = (Rotation.from_rotvec(v).as_matrix() for v in ([0, 0, 0.3], [0, -0.2, 0], [0.1, 0, 0]))
    np.testing.assert_allclose(T[:3, :3], Rz @ Ry @ Rx, atol=1e-12)
    np.testing.assert_allclose(g.rpy(T), [0.1, -0.2, 0.3], atol=1e-12)
    np.testing.assert_allclose(T[:3, 3], [1, 2, 3])


def test_invert_and_compose():
    rng = np.random.default_rng(0)
    T = g.from_rotvec(rng.normal(size=3), rng.normal(size=3))
    np.testing.assert_allclose(g.compose(T, g.invert(T)), np.eye(4), atol=1e-12)
    pts = rng.normal(size=(5, 3))
    np.testing.assert_allclose(g.transform_points(g.invert(T), g.transform_points(T, pts)), pts, atol=1e-12)


def test_rotation_distance_is_geodesic():
    A = g.from_rpy(0, 0, 0.2)
    B = g.from_rpy(0, 0, -0.5)
    assert g.rotation_distance(A, B) == pytest.approx(0.7)
    assert g.rotation_distance(A, A) == pytest.approx(0.0, abs=1e-9)
    assert g.rotation_distance(np.eye(4), g.from_rpy(np.pi, 0, 0)) == pytest.approx(np.pi)


def test_quaternion_is_xyzw():
    q = g.to_quat(g.from_rpy(0, 0, np.pi / 2))
    np.testing.assert_allclose(q, [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)], atol=1e-12)
    np.testing.assert_allclose(g.from_quat(q)[:3, :3], g.from_rpy(0, 0, np.pi / 2)[:3, :3], atol=1e-12)


@pytest.mark.parametrize(
    "bad, msg",
    [(np.eye(3), "4x4"), (np.diag([1, 1, 2, 1.0]), "rotation"), (np.vstack([np.eye(4)[:3], [1, 0, 0, 1]]), "last row")],
)
def test_as_transform_rejects_non_rigid(bad, msg):
    with pytest.raises(ValueError, match=msg):
        g.as_transform(bad)


def test_report_form_in_mm_and_degrees():
    rep = g.to_xyz_mm_rpy_deg(g.from_rpy(0, 0, np.radians(30), t=[0.001, 0, 0.5]))
    assert rep["xyz_mm"] == [1.0, 0.0, 500.0]
    assert rep["rpy_deg"][2] == pytest.approx(30.0)
