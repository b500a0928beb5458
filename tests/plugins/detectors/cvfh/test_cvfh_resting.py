"""Resting-pose hypotheses and hull twins of the CVFH detector (module resting)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from asmteach.core import geometry
from asmteach.core.interfaces import PartModel
from asmteach.core.models import Detection
from asmteach.core.parts import build_part, load_structure
from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings, look_at
from asmteach.plugins.detectors.cvfh.detector import CvfhIcpDetector
from asmteach.plugins.detectors.cvfh.resting import Disagreement, hull_twins, stable_rests
from asmteach.plugins.detectors.cvfh.scenes import default_camera_pose, place_on_table, render_table_scene

REPO = Path(__file__).resolve().parents[4]


@pytest.fixture(scope="module")
def peg_in_hole() -> tuple[PartModel, PartModel]:
    task = load_structure(REPO / "configs/parts/set1/peg_in_hole.yaml")
    return build_part(task.part_a), build_part(task.part_b)


@pytest.fixture(scope="module")
def detector(tmp_path_factory: pytest.TempPathFactory) -> CvfhIcpDetector:
    return CvfhIcpDetector({"views": {"cache_dir": str(tmp_path_factory.mktemp("views"))}}, seed=0)


def _detect(
    detector: CvfhIcpDetector,
    part: PartModel,
    T_world_part: np.ndarray,
    seed: int,
    T_world_cam: np.ndarray | None = None,
) -> Detection:
    T_world_cam = default_camera_pose() if T_world_cam is None else T_world_cam
    scene = render_table_scene(
        DepthCamera(KinectSettings(), seed=seed), part.mesh, T_world_part, T_world_cam=T_world_cam
    )
    detector.prepare(part)
    return detector.detect(scene.cloud, part, viewpoint=T_world_cam[:3, 3])


def _lying(part: PartModel, axis_world: np.ndarray, xy: tuple[float, float]) -> np.ndarray:
    """``T_world_part`` with the part's z axis along the horizontal ``axis_world``, resting on the table."""
    z = np.asarray(axis_world, float) / np.linalg.norm(axis_world)
    R = np.column_stack([np.array([0.0, 0.0, 1.0]), np.cross(z, [0.0, 0.0, 1.0]), z])
    return place_on_table(part.mesh, geometry.from_rotation(R), 0.0, xy)


def test_a_box_has_no_hull_twin_and_a_blind_hole_has_one(peg_in_hole: tuple[PartModel, PartModel]) -> None:
    box = trimesh.creation.box(extents=[0.08, 0.06, 0.04])
    assert hull_twins(box, np.zeros(3)) == []
    block = peg_in_hole[0]
    twins = hull_twins(block.mesh, np.asarray(block.center_of_mass))
    assert len(twins) == 1  # turning it over, about x or y: the same pose up to the block's own half turn
    assert twins[0][:3, 2] @ [0.0, 0.0, 1.0] == pytest.approx(-1.0)  # the hole now faces the other way


def test_stable_rests_stand_on_the_plane_centred() -> None:
    box = trimesh.creation.box(extents=[0.08, 0.06, 0.04])
    rests = stable_rests(box, np.zeros(3), 8)
    assert len(rests) == 6
    for T in rests:
        v = geometry.transform_points(T, box.vertices)
        assert v[:, 2].min() == pytest.approx(0.0, abs=1e-9)
        assert 0.5 * (v[:, :2].min(axis=0) + v[:, :2].max(axis=0)) == pytest.approx([0.0, 0.0], abs=1e-9)


def test_evidence_decides_only_when_one_side_has_enough() -> None:
    assert Disagreement(0, 24).verdict(10, 4.0) == "a"
    assert Disagreement(24, 0).verdict(10, 4.0) == "b"
    assert Disagreement(2, 6).verdict(10, 4.0) == "ambiguous"  # too few points either way
    assert Disagreement(22, 30).verdict(10, 4.0) == "ambiguous"  # both poses miss points: noise


def test_a_peg_showing_only_its_head_is_found_from_its_resting_poses(
    detector: CvfhIcpDetector, peg_in_hole: tuple[PartModel, PartModel]
) -> None:
    peg = peg_in_hole[1]
    # the simulated Nextage cell's camera, in front of the table; the peg lies on a head face with the
    # head towards the camera, which sees a cube and not the shank behind it (end-to-end seed 22)
    cam = look_at(np.array([1.05, 0.0, 0.75]), np.array([0.40, 0.22, 0.0]))
    T = _lying(peg, [0.93, 0.367, 0.0], (0.38, 0.22))
    det = _detect(detector, peg, T, seed=3, T_world_cam=cam)
    assert det.found, det.reason
    assert geometry.translation_distance(det.rough, T) < 0.003
    # the peg turns onto itself every 90 deg about its axis: compare the axes
    assert np.degrees(np.arccos(np.clip(det.rough[:3, 2] @ T[:3, 2], -1.0, 1.0))) < 3.0
    # whichever source found it, the resting hypotheses alone come within a yaw step of the truth
    from asmteach.core.models import TablePlane
    from asmteach.plugins.detectors.cvfh.resting import resting_hypotheses

    scene = render_table_scene(DepthCamera(KinectSettings(), seed=3), peg.mesh, T, T_world_cam=cam)
    cluster = scene.cloud[(scene.cloud[:, 2] > 0.006) & (np.linalg.norm(scene.cloud[:, :2] - T[:2, 3], axis=1) < 0.1)]
    prep = detector._prep(peg)
    hyps = resting_hypotheses(cluster, prep.model, prep.rests, TablePlane(), cam[:3, 3], 24)
    off = [
        (np.degrees(np.arccos(np.clip(H[:3, 2] @ T[:3, 2], -1, 1))), geometry.translation_distance(H, T))
        for H, _ in hyps
    ]
    assert min(a + 1000.0 * d for a, d in off) < 7.5 + 15.0  # <= half a 15 deg yaw step, ~1 cm


def test_a_hole_in_view_decides_between_the_twins_and_a_hidden_one_is_reported_ambiguous(
    detector: CvfhIcpDetector, peg_in_hole: tuple[PartModel, PartModel]
) -> None:
    block = peg_in_hole[0]
    cam = look_at(np.array([1.05, 0.0, 0.75]), np.array([0.38, 0.0, 0.0]))  # the simulated cell's camera
    seen = _lying(block, [1.0, 0.0, 0.0], (0.40, -0.20))  # the hole faces the camera
    det = _detect(detector, block, seen, seed=1, T_world_cam=cam)
    assert det.found, det.reason
    assert geometry.translation_distance(det.rough, seen) < 0.003
    assert "ambiguous" not in det.details

    hidden = _lying(block, [0.0, 1.0, 0.0], (0.35, 0.20))  # the hole faces away: only the outside is seen
    det = _detect(detector, block, hidden, seed=2, T_world_cam=cam)
    # the twin with the hole on the other side explains the view as well: either pose would be a guess
    assert not det.found and det.reason and "ambiguous" in det.reason, det.reason
    assert det.details["ambiguous_kind"] == "hull_twin"
    poses = [np.asarray(a["T_world_part"]) for a in det.details["ambiguous"]]
    assert len(poses) >= 2
    assert min(geometry.translation_distance(T, hidden) for T in poses) < 0.003


@pytest.mark.slow
@pytest.mark.parametrize(("rounds", "found"), [(8, True), (3, False)])
def test_a_peg_seen_end_on_in_the_simulated_cell_needs_the_resting_rounds(
    peg_in_hole: tuple[PartModel, PartModel], tmp_path: Path, rounds: int, found: bool
) -> None:
    """End-to-end seed 66: the peg lies with its head towards the camera, the block upside down beside it.

    Every yaw of the lying peg explains the square face it shows, so the right
    one ranks about 50th of the resting hypotheses: three rounds of ten missed it.
    """
    from asmteach.core import registry
    from asmteach.core.models import TablePlane

    block, peg = peg_in_hole
    T_block = geometry.from_rpy(np.pi, 0.0, np.radians(66.8948), t=[0.38963, 0.23076, 0.04])
    T_peg = geometry.from_rpy(-np.pi / 2, 0.0, np.radians(-97.2211), t=[0.30498, -0.14075, 0.02])
    robot = registry.create("robots", "nextage_pybullet", {}, seed=66)
    try:
        robot.reset_world(TablePlane(), {block.name: (block, T_block), peg.name: (peg, T_peg)})
        T_true = robot.part_pose(peg.name)
        _, cloud = robot.sense_depth()
        eye = robot.camera_pose()[:3, 3]
    finally:
        robot.close()
    detector = CvfhIcpDetector({"resting_rounds": rounds, "views": {"cache_dir": str(tmp_path)}}, seed=66)
    det = detector.detect(cloud, peg, TablePlane(), viewpoint=eye)
    assert det.found == found, det.reason
    if found:
        assert det.details["source"] == "resting"
        assert geometry.translation_distance(det.rough, T_true) < 0.002
        assert np.degrees(np.arccos(np.clip(det.rough[:3, 2] @ T_true[:3, 2], -1.0, 1.0))) < 2.0
