"""cvfh pinning: how well the seen points pin a pose's rotation down, and the rivals when they do not."""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from asmteach.core import geometry
from asmteach.core.models import TablePlane
from asmteach.core.perception.registration import model_cloud
from asmteach.core.symmetry.near import NearSymmetry
from asmteach.plugins.detectors.cvfh.pinning import free_axes, pin_rivals, rotation_sigma_deg
from asmteach.plugins.detectors.cvfh.pose_search import ClusterJob, Prepared
from asmteach.plugins.detectors.cvfh.settings import CvfhSettings


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


def _job(mesh: trimesh.Trimesh, seen: np.ndarray, same: NearSymmetry | None) -> tuple[np.ndarray, ClusterJob, Prepared]:
    model = model_cloud(mesh, 3000)
    prep = Prepared(model, None, 0.1, False, 0.0, np.zeros((0, 4, 4)), [], [], [np.eye(4)], None, same=same)  # type: ignore[arg-type]
    T = geometry.from_rotation(np.eye(3), (0.45, 0.0, 0.0))
    world = geometry.transform_points(T, seen)
    return T, ClusterJob(world, world, world, world, TablePlane(), np.array([0.0, 0.0, 0.7])), prep


def test_an_unpinned_pose_lists_itself_turned_both_ways_unless_every_turn_keeps_the_surface() -> None:
    # A 16-segment cylinder seen from above: the top face leaves the turn about the axis free. The listed
    # symmetries (free_axes at 0.5 mm) miss it: the facets sag 0.38 mm, so turns of 7 and 31 deg are not exact.
    cyl = trimesh.creation.cylinder(radius=0.02, height=0.03, sections=16)
    seen = _seen(cyl, [(0, 0, 1)])
    s = CvfhSettings()
    T, job, prep = _job(cyl, seen, None)
    sigma, rivals = pin_rivals(T, job, prep, s)
    assert s.pin_sigmas * sigma > s.distinct_deg and len(rivals) == 2  # turned +- 3 sigma: another view may judge
    for R in rivals:
        assert geometry.rotation_distance(R, T) > np.radians(s.distinct_deg)
    # every turn about the axis puts the surface where it was: no uncertainty of the answer
    T, job, prep = _job(cyl, seen, NearSymmetry(cyl))
    sigma, rivals = pin_rivals(T, job, prep, s)
    assert rivals == [] and s.pin_sigmas * sigma <= s.distinct_deg
    # a box's top face leaves its turn free too, and a box turned is another pose
    box = trimesh.creation.box((0.06, 0.04, 0.03))
    T, job, prep = _job(box, _seen(box, [(0, 0, 1)]), NearSymmetry(box))
    assert len(pin_rivals(T, job, prep, s)[1]) == 2


def test_at_rest_the_table_pins_the_tilts_and_the_view_only_the_turn_about_the_table_normal(d_peg_mesh) -> None:
    """A D peg lying on its flat, seen from above: the round side it shows leaves the roll about its axis free (a
    tilt), which the table pins when the pose rests on it; the turn about the table normal the long side pins."""
    lying = d_peg_mesh.copy()
    lying.apply_transform(geometry.from_rotvec([0.0, np.radians(90.0), 0.0]))  # the flat (+x) down, the axis along y
    pts, faces = trimesh.sample.sample_surface_even(lying, 6000, seed=0)
    seen = pts[np.asarray(lying.face_normals)[faces][:, 2] > 0.2]  # the round side, from above
    s = CvfhSettings()
    T, job, prep = _job(lying, seen, None)
    sigma, rivals = pin_rivals(T, job, prep, s)
    assert len(rivals) == 2
    roll = Rotation.from_matrix(rivals[0][:3, :3] @ T[:3, :3].T).as_rotvec()
    assert abs(roll @ [0.0, 1.0, 0.0]) > 0.95 * np.linalg.norm(roll)  # the rivals roll it about its axis
    at_rest, none = pin_rivals(T, job, prep, s, at_rest=True)
    assert none == [] and s.pin_sigmas * at_rest <= s.distinct_deg < s.pin_sigmas * sigma
