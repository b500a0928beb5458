"""cvfh pose search: how far apart two poses are, up to the part's own symmetries (mm, deg), and when two are
the same answer."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from asmteach.core import geometry
from asmteach.plugins.detectors.cvfh.pose_search import is_distinct, poses_apart
from asmteach.plugins.detectors.cvfh.settings import CvfhSettings


def _pose(yaw_deg: float, x: float = 0.0) -> np.ndarray:
    """A turn about world z by ``yaw_deg`` and a shift ``x`` metres along world x."""
    T = geometry.rot_z(np.radians(yaw_deg))
    T[0, 3] = x
    return T


def test_apart_measures_millimetres_and_degrees_to_the_nearest_symmetric_equivalent() -> None:
    mm, deg = poses_apart(_pose(0.0), _pose(30.0, 0.004), [np.eye(4)])
    assert mm == pytest.approx(4.0) and deg == pytest.approx(30.0)
    # a part that turns onto itself by 90 deg about z: 95 deg is 5 deg from its equivalent
    own = [_pose(a) for a in (0.0, 90.0, 180.0, 270.0)]
    mm, deg = poses_apart(_pose(0.0), _pose(95.0), own)
    assert mm == pytest.approx(0.0) and deg == pytest.approx(5.0)


def test_distinct_needs_to_be_beyond_either_limit_from_every_other_pose() -> None:
    s = CvfhSettings()  # distinct_mm = distinct_deg = 5
    own = [np.eye(4)]
    assert not is_distinct(_pose(4.0, 0.004), [_pose(0.0)], own, s)
    assert is_distinct(_pose(6.0), [_pose(0.0)], own, s)
    assert is_distinct(_pose(0.0, 0.006), [_pose(0.0)], own, s)
    assert not is_distinct(_pose(4.0), [_pose(20.0), _pose(0.0)], own, s)  # near the second
    # the near-twin screen asks at half the limits
    assert is_distinct(_pose(3.0), [_pose(0.0)], own, s, 0.5)
    assert is_distinct(_pose(0.0), [], own, s)


def test_a_pose_putting_the_surface_where_another_does_is_not_distinct() -> None:
    from asmteach.core.symmetry.near import NearSymmetry

    # a 16-segment cylinder turned 20 deg about its axis: no listed symmetry (those are 22.5 deg apart), the same
    # surface within 0.5 mm
    cyl = trimesh.creation.cylinder(radius=0.02, height=0.03, sections=16)
    B = geometry.from_rotation(np.eye(3), (0.45, 0.0, 0.1))
    A = B @ geometry.from_rotvec(np.radians(20.0) * np.array([0.0, 0.0, 1.0]))
    s = CvfhSettings()
    assert is_distinct(A, [B], [np.eye(4)], s)
    assert not is_distinct(A, [B], [np.eye(4)], s, same=NearSymmetry(cyl))
    tilted = B @ geometry.from_rotvec(np.radians(20.0) * np.array([1.0, 0.0, 0.0]))
    assert is_distinct(tilted, [B], [np.eye(4)], s, same=NearSymmetry(cyl))


def test_cluster_icp_registers_onto_the_seen_surface_only_when_visible_icp_is_set() -> None:
    """``refine.visible_icp`` makes the detector's ICP pass its camera centre to :func:`icp_refine`."""
    from asmteach.core.models import TablePlane
    from asmteach.core.perception.registration import RefineSettings, icp_refine, model_cloud
    from asmteach.plugins.detectors.cvfh.pose_search import ClusterJob

    box = trimesh.creation.box(extents=[0.04, 0.03, 0.02])
    model = model_cloud(box, 1000)
    eye = np.array([0.3, 0.0, 0.4])
    # only the faces the eye sees, as a camera would give them, and a start 2 mm / 3 deg off
    seen = model.points[model.normals @ np.array([1.0, 0.0, 1.0]) > 0.1]
    T0 = _pose(3.0, 0.002)
    job = ClusterJob(seen, seen, seen, seen, TablePlane(height=-0.01), eye)
    on, off = RefineSettings(), RefineSettings(visible_icp=False)
    assert job.icp(seen, model, T0, on) == pytest.approx(icp_refine(seen, model, T0, on, viewpoint=eye), abs=1e-12)
    assert job.icp(seen, model, T0, off) == pytest.approx(icp_refine(seen, model, T0, off), abs=1e-12)
    assert job.icp_passes == 4
