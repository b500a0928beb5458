"""cvfh pose search: how far apart two poses are, up to the part's own symmetries (mm, deg), and how well the
seen points pin a pose's rotation down."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from asmteach.core import geometry
from asmteach.core.models import TablePlane
from asmteach.core.perception.registration import model_cloud
from asmteach.plugins.detectors.cvfh.pose_search import (
    ClusterJob,
    Prepared,
    free_axes,
    is_distinct,
    poses_apart,
    rotation_sigma_deg,
)
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


def _seen(mesh: trimesh.Trimesh, normals: list[tuple[float, float, float]], seed: int = 0) -> np.ndarray:
    """Surface samples of ``mesh`` on the faces whose normal is one of ``normals`` (what a camera sees)."""
    pts, faces = trimesh.sample.sample_surface_even(mesh, 4000, seed=seed)
    n = np.asarray(mesh.face_normals)[faces]
    keep = np.zeros(len(pts), dtype=bool)
    for v in normals:
        keep |= n @ np.asarray(v, float) > 0.99
    return pts[keep]


def _sigma(mesh: trimesh.Trimesh, seen: np.ndarray, free: np.ndarray | None = None) -> float:
    model = model_cloud(mesh, 3000)
    prep = Prepared(model, None, 0.1, False, 0.0, np.zeros((0, 4, 4)), [], [], [np.eye(4)], None)  # type: ignore[arg-type]
    if free is not None:
        prep.free = free
    T = geometry.from_rotation(np.eye(3), (0.45, 0.0, 0.0))  # the part 0.45 m ahead, the camera above it
    world = geometry.transform_points(T, seen)
    job = ClusterJob(world, world, world, world, TablePlane(), np.array([0.0, 0.0, 0.7]))
    return rotation_sigma_deg(T, job, prep, 0.004)


def test_three_faces_of_a_block_pin_its_rotation_down_and_one_face_does_not() -> None:
    box = trimesh.creation.box((0.06, 0.04, 0.03))
    three = _sigma(box, _seen(box, [(0, 0, 1), (-1, 0, 0), (0, -1, 0)]))
    assert three < 0.5  # a fraction of a degree from a few hundred points
    # the top face alone lets the block turn about its normal: nothing pins that turn
    assert _sigma(box, _seen(box, [(0, 0, 1)])) > 10.0 * three


def test_an_axis_of_revolution_is_free_and_left_out_of_the_rotation_uncertainty() -> None:
    tube = trimesh.creation.cylinder(radius=0.015, height=0.08, sections=64)
    free = free_axes(tube, np.zeros(3), 0.0005)
    assert len(free) == 1 and abs(free[0] @ [0.0, 0.0, 1.0]) > 0.999
    assert len(free_axes(trimesh.creation.box((0.06, 0.04, 0.03)), np.zeros(3), 0.0005)) == 0
    side = _seen(tube, [(-1, 0, 0)] + [(-np.cos(a), -np.sin(a), 0) for a in np.radians(np.arange(-60, 61, 6))])
    pinned = _sigma(tube, side, free)
    assert pinned < 1.0  # the other turns are pinned down ...
    assert _sigma(tube, side) > 5.0 * pinned  # ... the turn about its own axis is not (only the facets tell)


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
