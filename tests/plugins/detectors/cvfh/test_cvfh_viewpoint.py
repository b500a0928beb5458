"""The ``viewpoint`` argument of ``cvfh_icp``: a camera at the robot's Kinect, the argument against the setting,
no viewpoint at all, bad viewpoints, and where ``asmteach detect`` takes it from (``--viewpoint``, a PLY comment,
a PCD header, else exit 2)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from asmteach.core import geometry
from asmteach.core.cli import main
from asmteach.core.detect_correct import detect_and_correct
from asmteach.core.errors import UserError
from asmteach.core.interfaces import PartModel
from asmteach.core.models import Placement
from asmteach.core.parts import build_part, load_structure
from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings, look_at
from asmteach.core.perception.viewpoint import NO_VIEWPOINT
from asmteach.plugins.detectors.cvfh.detector import CvfhIcpDetector
from asmteach.plugins.detectors.cvfh.scenes import TableScene, place_on_table, render_table_scene
from asmteach.plugins.planners.placements.corrector import StablePlacementCorrector

import open3d as o3d  # isort: skip

REPO = Path(__file__).resolve().parents[4]
STRUCTURE = REPO / "configs/parts/set1/l_corner.yaml"
ROBOT_EYE = np.array([1.05, 0.0, 0.75])
"""Where the robot's Kinect sits (world, metres; table top at z = 0), looking at the work centre."""
ROBOT_TARGET = np.array([0.45, 0.0, 0.0])


@pytest.fixture(scope="module")
def l_block() -> PartModel:
    return build_part(load_structure(STRUCTURE).part_a)


@pytest.fixture(scope="module")
def placements(l_block: PartModel) -> list[Placement]:
    from asmteach.core.rests.placements import compute_placements

    return compute_placements(l_block)


@pytest.fixture(scope="module")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("views_viewpoint")


@pytest.fixture(scope="module")
def detector(cache: Path, l_block: PartModel) -> CvfhIcpDetector:
    det = CvfhIcpDetector({"views": {"cache_dir": str(cache)}}, seed=0)
    det.prepare(l_block)
    return det


def _robot_scene(
    part: PartModel, T_table_part: np.ndarray, yaw: float, xy: tuple[float, float], seed: int
) -> TableScene:
    T = place_on_table(part.mesh, T_table_part, yaw, xy)
    return render_table_scene(
        DepthCamera(KinectSettings(), seed=seed), part.mesh, T, T_world_cam=look_at(ROBOT_EYE, ROBOT_TARGET)
    )


@pytest.mark.parametrize(
    ("placement", "yaw_deg", "xy"),
    [(0, 25.0, (0.40, 0.08)), (1, -100.0, (0.50, -0.10)), (2, 150.0, (0.45, 0.02))],
)
def test_finds_and_corrects_with_the_robot_camera(
    detector: CvfhIcpDetector, l_block: PartModel, placements: list[Placement], placement: int, yaw_deg: float, xy
) -> None:
    scene = _robot_scene(l_block, placements[placement].T_table_part, np.radians(yaw_deg), xy, seed=20 + placement)
    corrector = StablePlacementCorrector({}, seed=0)
    det = detect_and_correct(detector, corrector, scene.cloud, l_block, viewpoint=ROBOT_EYE)
    assert det.found, det.reason
    assert np.allclose(det.details["viewpoint"], ROBOT_EYE)
    assert geometry.translation_distance(det.rough, scene.T_world_part) < 0.003
    assert np.degrees(geometry.rotation_distance(det.rough, scene.T_world_part)) < 3.0
    # The corrector got the viewpoint too and matched the visible model surface: the xy and yaw targets.
    assert det.corrected is not None
    xy_err = np.linalg.norm(det.corrected[:2, 3] - scene.T_world_part[:2, 3])
    assert xy_err <= 0.0015
    assert np.degrees(geometry.rotation_distance(det.corrected, scene.T_world_part)) <= 2.0


def test_argument_equals_setting_and_overrides_it(
    detector: CvfhIcpDetector, cache: Path, l_block: PartModel, placements: list[Placement]
) -> None:
    scene = _robot_scene(l_block, placements[0].T_table_part, 0.7, (0.47, -0.05), seed=5)
    by_setting = CvfhIcpDetector({"views": {"cache_dir": str(cache)}, "viewpoint": ROBOT_EYE.tolist()}, seed=0)
    a = detector.detect(scene.cloud, l_block, viewpoint=ROBOT_EYE)  # default setting, overridden
    b = by_setting.detect(scene.cloud, l_block)
    assert a.found and b.found
    assert np.allclose(a.rough, b.rough, atol=1e-6)  # the same pose (up to Open3D float rounding)
    assert np.allclose(b.details["viewpoint"], ROBOT_EYE)
    # Neither the argument nor the setting: no guessed camera, one clear error naming what to give.
    with pytest.raises(UserError, match="no camera position") as err:
        detector.detect(scene.cloud, l_block)
    assert str(err.value) == NO_VIEWPOINT and "--viewpoint" in NO_VIEWPOINT


@pytest.mark.parametrize(
    ("viewpoint", "words"),
    [
        (ROBOT_EYE * 1000.0, "millimetres|not mm"),
        (np.array([1.0, 0.0]), "3 finite numbers"),
        (np.array([1.0, np.nan, 0.5]), "3 finite numbers"),
    ],
)
def test_bad_viewpoint_is_one_clear_error(
    detector: CvfhIcpDetector, l_block: PartModel, viewpoint: np.ndarray, words: str
) -> None:
    with pytest.raises(UserError, match=words):
        detector.detect(np.zeros((10, 3)), l_block, viewpoint=viewpoint)


def test_cli_viewpoint_option(
    l_block: PartModel,
    placements: list[Placement],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    cache: Path,
) -> None:
    scene = _robot_scene(l_block, placements[1].T_table_part, -0.4, (0.43, 0.06), seed=8)
    ply = tmp_path / "scene.ply"
    o3d.io.write_point_cloud(str(ply), o3d.geometry.PointCloud(o3d.utility.Vector3dVector(scene.cloud)))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    out = tmp_path / "detection.json"
    args = ["detect", str(STRUCTURE), "--cloud", str(ply), "--out", str(out), "--viewpoint", *map(str, ROBOT_EYE)]
    assert main(args) == 0, capsys.readouterr()
    doc = json.loads(out.read_text())
    assert doc["found"] and np.allclose(doc["details"]["viewpoint"], ROBOT_EYE)
    corrected = np.asarray(doc["corrected"]["T_world_part"])
    assert np.linalg.norm(corrected[:2, 3] - scene.T_world_part[:2, 3]) <= 0.0015
    # A viewpoint in millimetres: one line, exit 2.
    bad = ["detect", str(STRUCTURE), "--cloud", str(ply), "--out", str(out), "--viewpoint", "1050", "0", "750"]
    assert main(bad) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def _pcd_with_viewpoint(path: Path, points: np.ndarray, eye: np.ndarray) -> Path:
    """An ASCII PCD (Open3D's writer) whose VIEWPOINT header holds ``eye`` (PCL: translation, then a quaternion)."""
    o3d.io.write_point_cloud(str(path), o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)), write_ascii=True)
    lines = path.read_text().splitlines()
    i = next(k for k, line in enumerate(lines) if line.startswith("VIEWPOINT"))
    assert lines[i].split()[1:] == ["0", "0", "0", "1", "0", "0", "0"]  # what every writer puts by default
    lines[i] = "VIEWPOINT " + " ".join(map(str, eye)) + " 1 0 0 0"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_cli_viewpoint_from_the_cloud_file_else_exit_2(
    l_block: PartModel,
    placements: list[Placement],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    cache: Path,
) -> None:
    scene = _robot_scene(l_block, placements[0].T_table_part, 1.1, (0.46, -0.03), seed=12)
    monkeypatch.setenv("XDG_CACHE_HOME", str(cache / "xdg"))
    out = tmp_path / "detection.json"

    def detect(cloud: Path) -> int:
        return main(["detect", str(STRUCTURE), "--cloud", str(cloud), "--out", str(out), "--no-correct"])

    # A PLY from asmteach's renderer carries the camera centre ('comment viewpoint'); a PCD its VIEWPOINT header.
    for cloud in (
        scene.frame.write_ply(tmp_path / "scene.ply"),
        _pcd_with_viewpoint(tmp_path / "scene.pcd", scene.cloud, ROBOT_EYE),
    ):
        assert detect(cloud) == 0, capsys.readouterr()
        doc = json.loads(out.read_text())
        assert np.allclose(doc["details"]["viewpoint"], ROBOT_EYE, atol=1e-6), cloud.name
        assert geometry.translation_distance(np.asarray(doc["rough"]["T_world_part"]), scene.T_world_part) < 0.003
    out.unlink()
    # A PLY that says nothing, and no --viewpoint: exit 2, one line naming what to give, no detection written.
    bare = tmp_path / "bare.ply"
    o3d.io.write_point_cloud(str(bare), o3d.geometry.PointCloud(o3d.utility.Vector3dVector(scene.cloud)))
    assert detect(bare) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no camera position" in err[0] and "--viewpoint" in err[0], err
    assert not out.exists()
