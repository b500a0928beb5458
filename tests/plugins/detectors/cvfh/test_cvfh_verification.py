"""Verification never lets a wrong pose through: the model-side surface check, and near twins of a part
the view cannot tell apart (issue 22: poses 17-20 mm / 66-105 deg off were reported as found)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from asmteach.core import geometry
from asmteach.core.corpus import corpus_part
from asmteach.core.interfaces import PartModel
from asmteach.core.models import TablePlane
from asmteach.core.parts import PartSpec, build_part
from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings
from asmteach.core.perception.registration import RefineSettings, check_surface, icp_refine, model_cloud, verify
from asmteach.core.rests.drops import drop_rests
from asmteach.core.symmetry import part_symmetries
from asmteach.plugins.detectors.cvfh.detector import CvfhIcpDetector
from asmteach.plugins.detectors.cvfh.resting import near_twins
from asmteach.plugins.detectors.cvfh.scenes import (
    DEFAULT_EYE,
    default_camera_pose,
    place_on_table,
    render_table_scene,
)


@pytest.fixture(scope="module")
def keyed_peg(tmp_path_factory: pytest.TempPathFactory) -> PartModel:
    """A peg with a small key along its side (a corpus part the detector was never tuned on)."""
    path = tmp_path_factory.mktemp("keyed") / "keyed_peg_1.stl"
    corpus_part("keyed_peg_1").mesh.export(path)
    return build_part(PartSpec(name="keyed_peg_1", mesh=str(path), mesh_units="m"))


def _lying_scene(part: PartModel, yaw: float, seed: int):  # type: ignore[no-untyped-def]
    """The part in its likeliest stable rest at ``yaw``, seen by the scene Kinect."""

    T, p = drop_rests(part.mesh, part.center_of_mass)
    T_true = place_on_table(part.mesh, T[int(np.argmax(p))], yaw, (0.47, 0.03))
    return render_table_scene(
        DepthCamera(KinectSettings(), seed=seed), part.mesh, T_true, T_world_cam=default_camera_pose()
    )


def _error(T: np.ndarray, T_true: np.ndarray, own: list[np.ndarray]) -> tuple[float, float]:
    """(mm, deg) to the nearest symmetric equivalent of the truth."""
    errs = [
        (1000 * geometry.translation_distance(T, T_true @ S), math.degrees(geometry.rotation_distance(T, T_true @ S)))
        for S in own
    ]
    return min(errs, key=sum)


def test_a_pose_20mm_70deg_off_is_rejected_and_the_true_one_accepted(keyed_peg: PartModel) -> None:
    scene = _lying_scene(keyed_peg, 0.8, seed=4)
    cluster = scene.cloud[scene.frame.labels == 1]
    context = scene.cloud[np.linalg.norm(scene.cloud - cluster.mean(axis=0), axis=1) < 0.1]
    model = model_cloud(keyed_peg.mesh, 4000)
    s, table = RefineSettings(), TablePlane(height=0.0)
    assert verify(scene.T_world_part, cluster, context, DEFAULT_EYE, model, s, table).accepted
    c = geometry.transform_points(scene.T_world_part, np.asarray(keyed_peg.center_of_mass)[None])[0]
    R = geometry.rot_z(np.radians(70.0))[:3, :3]
    turn = geometry.from_rotation(R, c - R @ c)  # 70 deg about the vertical through the centre of mass
    T_off = geometry.from_rotation(np.eye(3), [0.02, 0.0, 0.0]) @ turn @ scene.T_world_part
    own = part_symmetries(keyed_peg.mesh, np.asarray(keyed_peg.center_of_mass))
    mm, deg = _error(T_off, scene.T_world_part, own)
    assert mm > 15.0 and deg > 60.0
    v = verify(T_off, cluster, context, DEFAULT_EYE, model, s, table)
    assert not v.accepted and v.why
    # The model side: at the wrong pose the camera saw through much of the surface the model shows it.
    check = check_surface(geometry.invert(T_off), context, DEFAULT_EYE, model, s)
    right = check_surface(geometry.invert(scene.T_world_part), context, DEFAULT_EYE, model, s)
    assert check.contradicted > 2 * s.max_contradicted and check.coverage < 0.5
    assert right.coverage > s.min_coverage and right.contradicted < s.max_contradicted
    # ICP from the wrong pose either finds the truth or stays a pose verification rejects.
    T = icp_refine(cluster, model, T_off, s)
    if _error(T, scene.T_world_part, own) > (5.0, 5.0):
        assert not verify(T, cluster, context, DEFAULT_EYE, model, s, table).accepted


def test_near_twins_of_a_keyed_peg_turn_about_its_axis(keyed_peg: PartModel) -> None:
    com = np.asarray(keyed_peg.center_of_mass)
    twins = near_twins(keyed_peg.mesh, com, 0.002)
    m = keyed_peg.mesh
    axis = np.asarray(m.principal_inertia_vectors)[np.argmin(m.principal_inertia_components)]  # the long axis
    about_axis = [S for S in twins if abs(abs(np.dot(_rot_axis(S[:3, :3]), axis)) - 1.0) < 1e-3]
    assert len(about_axis) >= 5  # the key is small: most turns about the axis keep the surface within 2 mm
    for S in twins:  # each maps the centre of mass onto itself and is no symmetry of the part
        assert np.allclose(geometry.transform_points(S, com[None])[0], com, atol=1e-9)
        assert not np.allclose(S[:3, :3], np.eye(3), atol=1e-6)


def _rot_axis(R: np.ndarray) -> np.ndarray:
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if np.linalg.norm(w) < 1e-9:  # a half turn: the axis is the eigenvector of eigenvalue 1
        vals, vecs = np.linalg.eigh(R + R.T)
        return vecs[:, np.argmax(vals)]
    return w / np.linalg.norm(w)


@pytest.mark.slow
@pytest.mark.parametrize(("yaw", "seed"), [(0.8, 4), (-2.0, 7)])
def test_a_keyed_peg_is_found_right_or_not_found_never_wrong(
    keyed_peg: PartModel, tmp_path_factory: pytest.TempPathFactory, yaw: float, seed: int
) -> None:
    """Without the near-twin check (``near_twin_tol: 0, nudge_deg: 0``) these two scenes come back as found,
    23 and 86 deg off about the peg's axis (the key is out of sight or too small to pin the turn)."""
    det = CvfhIcpDetector({"views": {"cache_dir": str(tmp_path_factory.getbasetemp() / "views")}}, seed=0)
    scene = _lying_scene(keyed_peg, yaw, seed)
    d = det.detect(scene.cloud, keyed_peg, viewpoint=DEFAULT_EYE)
    if d.found:
        own = part_symmetries(keyed_peg.mesh, np.asarray(keyed_peg.center_of_mass))
        mm, deg = _error(d.rough, scene.T_world_part, own)
        assert mm <= 5.0 and deg <= 5.0, (mm, deg)
    else:
        assert "ambiguous" in d.reason and "deg away" in d.reason, d.reason
        # the poses it cannot tell apart, for callers that must not read the reason (the pipeline's failure cause)
        assert len(d.details["ambiguous"]) == 2 and all(
            np.shape(a["T_world_part"]) == (4, 4) for a in d.details["ambiguous"]
        )


def test_the_fitness_test_allows_for_the_depth_noise_at_the_cluster_range(keyed_peg: PartModel) -> None:
    """The true pose seen from 1.4 m, its points off the surface along their rays by the Kinect's noise there
    (3.3 mm, twice that at 0.85 m): 4 mm of the surface holds 94 % of them, below min_fitness, and the pose
    was rejected; the noise-scaled test accepts it. Its score keeps the fixed inlier distance."""
    from asmteach.core.clouds import depth_sigma
    from asmteach.core.perception.registration import noise_scale
    from asmteach.core.perception.surface_check import ray_depths

    model = model_cloud(keyed_peg.mesh, 4000)
    T_true = geometry.from_rotvec([math.pi / 2, 0.0, 0.3])
    T_true[:3, 3] = [0.4, 0.1, 0.02]
    eye = np.array([0.4, 0.1, 0.02]) + 1.4 * np.array([0.6, 0.0, 0.8])
    eye_local = geometry.transform_points(geometry.invert(T_true), eye[None])[0]
    hit, dist = ray_depths(model, eye_local, model.points)
    seen = (np.abs(hit - dist) < 1e-4) & (np.einsum("ij,ij->i", eye_local - model.points, model.normals) > 0)
    world = geometry.transform_points(T_true, model.points[seen])
    rays = (world - eye) / np.linalg.norm(world - eye, axis=1)[:, None]
    rng = np.random.default_rng(5)
    cluster = (
        world + rays * rng.normal(0.0, 1.0, (len(world), 1)) * depth_sigma(np.linalg.norm(world - eye, axis=1))[:, None]
    )
    assert noise_scale(cluster, eye, 0.85).min() > 1.8
    unscaled = verify(T_true, cluster, cluster, eye, model, RefineSettings(noise_range=10.0))
    assert not unscaled.accepted and "fitness" in (unscaled.why or "")
    v = verify(T_true, cluster, cluster, eye, model, RefineSettings())
    assert v.accepted, v.why
    assert v.fitness == pytest.approx(unscaled.fitness)
    assert noise_scale(eye[None] + [[0.5, 0.0, 0.0]], eye, 0.85)[0] == 1.0  # nearer points keep the measured distance
