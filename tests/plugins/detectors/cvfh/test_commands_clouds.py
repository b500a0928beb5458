"""``asmteach detect`` on a sensor's own file: an organized camera-frame Kinect PCD, put in the world by extrinsics
or by the table plane; a world-frame PCD whose VIEWPOINT gives the camera."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from asmteach.core import clouds, geometry
from asmteach.core.cli import main
from asmteach.core.config import TableSettings
from asmteach.core.parts import build_part, load_structure
from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings
from asmteach.plugins.detectors.cvfh.scenes import place_on_table, render_table_scene

REPO = Path(__file__).resolve().parents[4]
STRUCTURE = REPO / "configs/parts/set1/l_corner.yaml"
TABLE = TableSettings(height=0.0, center=(0.45, 0.0), size=(0.8, 1.2))


@pytest.fixture(scope="module")
def kinect_file(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray, np.ndarray, Path]:
    """(camera-frame organized PCD, T_world_part, T_world_cam, folder) of a rendered L-block on the table."""
    folder = tmp_path_factory.mktemp("detect_kinect")
    part = build_part(load_structure(STRUCTURE).part_a)
    T = place_on_table(part.mesh, np.eye(4), 0.6, (0.47, -0.04))
    frame = render_table_scene(DepthCamera(KinectSettings(), seed=11), part.mesh, T, table=TABLE).frame
    h, w = frame.depth.shape
    grid = np.full((h, w, 3), np.nan)
    grid[frame.pixels[:, 0], frame.pixels[:, 1]] = frame.points_cam
    labels = np.zeros((h, w), np.uint32)
    labels[frame.pixels[:, 0], frame.pixels[:, 1]] = frame.labels.astype(np.uint32)
    path = clouds.write_pcd(
        folder / "kinect.pcd",
        grid.reshape(-1, 3),
        fields={"label": labels.ravel()},
        width=w,
        height=h,
        data="binary_compressed",
    )
    world = clouds.write_pcd(folder / "world.pcd", frame.points_world, T_data_sensor=frame.T_world_cam)
    assert world.is_file()
    return path, T, frame.T_world_cam, folder


def _close(T_a: np.ndarray, T_b: np.ndarray) -> bool:
    return geometry.translation_distance(T_a, T_b) < 0.003 and np.degrees(geometry.rotation_distance(T_a, T_b)) < 3.0


def test_camera_frame_cloud_with_extrinsics_and_table_plane(
    kinect_file: tuple[Path, np.ndarray, np.ndarray, Path],
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    pcd, T, T_world_cam, folder = kinect_file
    monkeypatch.setenv("XDG_CACHE_HOME", str(folder / "cache"))
    flat = ", ".join(f"{v:.12g}" for v in T_world_cam.ravel())
    ext = folder / "extrinsics.yaml"
    ext.write_text(f"T_world_cam: {{rows: 4, cols: 4, data: [{flat}]}}\n")
    out = folder / "ext.json"
    assert main(["detect", str(STRUCTURE), "--cloud", str(pcd), "--out", str(out), "--extrinsics", str(ext)]) == 0
    doc = json.loads(out.read_text())
    assert doc["frame_source"] == "extrinsics" and "extrinsics" in doc["frame"]
    assert np.allclose(doc["details"]["viewpoint"], T_world_cam[:3, 3])  # the camera centre is the pose's origin
    for key in ("rough", "corrected"):
        assert _close(np.asarray(doc[key]["T_world_part"]), T), key
    # No extrinsics: the table plane gives a world with z up and the table at z = 0; its x, y differ from the
    # truth's, so the pose is compared in the camera frame.
    out = folder / "plane.json"
    assert main(["detect", str(STRUCTURE), "--cloud", str(pcd), "--out", str(out)]) == 0
    assert "table_plane" in capsys.readouterr().out
    doc = json.loads(out.read_text())
    assert doc["frame_source"] == "table_plane" and "auto" in doc["frame"]
    T_cam_part = geometry.invert(T_world_cam) @ T
    for key in ("rough", "corrected"):
        assert _close(np.asarray(doc["camera_frame"][key]["T_cam_part"]), T_cam_part), key
    assert abs(doc["corrected"]["xyz_mm"][2]) < 1.0  # rests on the table at z = 0 of the plane frame
    # Forced to be read as a world-frame cloud it has no camera centre: one line, exit 2.
    assert main(["detect", str(STRUCTURE), "--cloud", str(pcd), "--out", str(out), "--frame", "world"]) == 2
    assert "--viewpoint" in capsys.readouterr().err


def test_world_frame_pcd_with_its_viewpoint(
    kinect_file: tuple[Path, np.ndarray, np.ndarray, Path],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    _, T, T_world_cam, folder = kinect_file
    monkeypatch.setenv("XDG_CACHE_HOME", str(folder / "cache"))
    out = folder / "world.json"
    assert main(["detect", str(STRUCTURE), "--cloud", str(folder / "world.pcd"), "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["frame_source"] == "world" and "camera_frame" not in doc
    assert np.allclose(doc["details"]["viewpoint"], T_world_cam[:3, 3], atol=1e-6)  # from the PCD VIEWPOINT
    assert _close(np.asarray(doc["corrected"]["T_world_part"]), T)
