"""``asmteach detect``: a scene PLY in, detection.json out; bad input gives a reason or one line and exit 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import asmteach.core  # noqa: F401  (libusb before open3d)
from asmteach.core import geometry
from asmteach.core.cli import main
from asmteach.core.parts import build_part, load_structure
from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings, write_cloud_ply
from asmteach.plugins.detectors.cvfh.scenes import DEFAULT_EYE, place_on_table, render_table_scene

import open3d as o3d  # isort: skip

REPO = Path(__file__).resolve().parents[4]
STRUCTURE = REPO / "configs/parts/set1/l_corner.yaml"


def _write_cloud(path: Path, points: np.ndarray) -> Path:
    """A PLY of the scene renderer's camera, which carries its centre ('comment viewpoint X Y Z')."""
    return write_cloud_ply(path, points, DEFAULT_EYE)


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray, Path]:
    folder = tmp_path_factory.mktemp("detect_cli")
    part = build_part(load_structure(STRUCTURE).part_a)
    T = place_on_table(part.mesh, np.eye(4), 0.6, (0.47, -0.04))
    sc = render_table_scene(DepthCamera(KinectSettings(), seed=11), part.mesh, T)
    return _write_cloud(folder / "scene.ply", sc.cloud), T, folder


def test_detect_structure_writes_rough_and_corrected(
    scene: tuple[Path, np.ndarray, Path], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    ply, T, folder = scene
    monkeypatch.setenv("XDG_CACHE_HOME", str(folder / "cache"))
    out = folder / "detection.json"
    code = main(["detect", str(STRUCTURE), "--cloud", str(ply), "--out", str(out)])
    assert code == 0, capsys.readouterr()
    doc = json.loads(out.read_text())
    assert doc["found"] is True and doc["reason"] is None and doc["part"] == "l_block"
    for key in ("rough", "corrected"):
        pose = np.asarray(doc[key]["T_world_part"])
        assert pose.shape == (4, 4)
        assert geometry.translation_distance(pose, T) < 0.003
        assert np.degrees(geometry.rotation_distance(pose, T)) < 3.0
        assert np.allclose(doc[key]["xyz_mm"], pose[:3, 3] * 1000.0, atol=1e-3)
        assert np.allclose(doc[key]["rpy_deg"], np.degrees(geometry.rpy(pose)), atol=1e-3)
    # The corrected pose rests exactly on the (fitted) table: z of the origin is the table height.
    assert abs(doc["corrected"]["xyz_mm"][2]) < 0.5
    assert 0.9 < doc["fitness"] <= 1.0
    t = doc["timing_ms"]
    assert {"segment", "cluster", "descriptors", "matching", "icp", "verify", "detect", "correct", "total"} <= set(t)
    assert t["total"] == pytest.approx(t["detect"] + t["correct"], abs=0.02)
    assert (folder / "cache" / "asmteach" / "cvfh_views").is_dir()  # the view database was cached


def test_detect_bad_input(
    scene: tuple[Path, np.ndarray, Path], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    ply, _, folder = scene
    monkeypatch.setenv("XDG_CACHE_HOME", str(folder / "cache"))
    out = folder / "bad.json"
    # A missing cloud file: one line, exit 2, no file written.
    assert main(["detect", str(STRUCTURE), "--cloud", str(folder / "none.ply"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no such file" in err[0] and not out.exists()
    # A part file that does not exist, and a file that is no cloud: exit 2 as well.
    assert main(["detect", str(folder / "nope.yaml"), "--cloud", str(ply), "--out", str(out)]) == 2
    assert main(["detect", str(STRUCTURE), "--cloud", str(STRUCTURE), "--out", str(out)]) == 2
    capsys.readouterr()
    # A cloud in millimetres given as metres, and an empty cloud: the cloud reader refuses them in one line.
    points = np.asarray(o3d.io.read_point_cloud(str(ply)).points)
    for name, cloud, words, extra in (
        ("mm.ply", points * 1000.0, "millimetres", ["--cloud-units", "m"]),
        ("empty.ply", np.zeros((0, 3)), "no points", []),
    ):
        path = _write_cloud(folder / name, cloud)
        assert main(["detect", str(STRUCTURE), "--cloud", str(path), "--out", str(out), *extra]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and words in err[0] and not out.exists()
