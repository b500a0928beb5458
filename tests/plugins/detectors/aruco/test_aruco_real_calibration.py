"""``asmteach calibrate`` on real chessboard photos (OpenCV's left01..14.jpg) against OpenCV's own calibration."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import cv2
import numpy as np
import pytest

from asmteach.core.cli import main
from asmteach.plugins.detectors.aruco.camera import load_camera


def _reference(real_data: Path) -> tuple[np.ndarray, float]:
    fs = cv2.FileStorage(str(real_data / "real/chessboard/reference_left_intrinsics.yml"), cv2.FILE_STORAGE_READ)
    try:
        assert int(fs.getNode("flags").real()) == cv2.CALIB_FIX_ASPECT_RATIO
        return fs.getNode("camera_matrix").mat(), fs.getNode("avg_reprojection_error").real()
    finally:
        fs.release()


def test_chessboard_calibration_matches_opencv_reference(
    real_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "left.yaml"
    argv = [
        "calibrate",
        "--images",
        str(real_data / "real/chessboard"),
        "--out",
        str(out),
        "--board",
        "chessboard",
        "--cols",
        "9",
        "--rows",
        "6",
        "--square",
        "0.025",
        "--fix-aspect",
    ]
    assert main(argv) == 0
    text = capsys.readouterr().out
    K_ref, rms_ref = _reference(real_data)
    cam = load_camera(out)  # the file the teacher reads
    K = cam.K
    assert (cam.width, cam.height) == (640, 480) and len(cam.dist) == 5
    assert abs(K[0, 0] / K_ref[0, 0] - 1) < 0.005 and abs(K[1, 1] / K_ref[1, 1] - 1) < 0.005
    assert K[0, 0] == pytest.approx(K[1, 1], rel=1e-12)  # fixed aspect ratio, as the reference
    assert abs(K[0, 2] - K_ref[0, 2]) < 2.0 and abs(K[1, 2] - K_ref[1, 2]) < 2.0
    rms = float(text.split("RMS ")[1].split(" px")[0])
    assert rms <= 0.45 and abs(rms - rms_ref) < 0.05
    assert "13/13" in text and "CALIB_FIX_ASPECT_RATIO" in text
    # Per-view errors: one per photo; left02.jpg is the worst view in OpenCV's reference too (1.18 px).
    per_view = dict(item.rsplit(" ", 1) for item in text.split("per-view RMS (px): ")[1].splitlines()[0].split(", "))
    assert len(per_view) == 13 and max(per_view, key=lambda n: float(per_view[n])) == "left02.jpg"
    png = cv2.imread(str(tmp_path / "left_coverage.png"))
    assert png is not None and png.shape == (480, 640, 3)
    assert png.reshape(-1, 3).std(axis=0).max() > 5  # corners drawn, not a blank canvas


def test_unreadable_board_photos_are_named_and_none_is_an_error(
    real_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "photos"
    folder.mkdir()
    for name in ("left01.jpg", "left03.jpg", "left04.jpg", "left05.jpg"):
        (folder / name).symlink_to(real_data / "real/chessboard" / name)
    cv2.imwrite(str(folder / "wall.png"), np.full((480, 640, 3), 128, np.uint8))
    argv = [
        "calibrate",
        "--images",
        str(folder),
        "--out",
        str(tmp_path / "c.yaml"),
        "--board",
        "chessboard",
        "--cols",
        "9",
        "--rows",
        "6",
        "--square",
        "0.025",
    ]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "wall.png: board not found, skipped" in text and "4/5" in text and "fx, fy free" in text
    # The same photos read as a 9x7 board: no view matches, a user error (exit 2) naming the board.
    argv[argv.index("6")] = "7"
    assert main(argv) == 2
    assert "chessboard 9x7 inner corners" in capsys.readouterr().err


def test_missing_real_data_skips_locally_and_fails_under_ci(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    spec = importlib.util.spec_from_file_location("aruco_conftest", Path(__file__).with_name("conftest.py"))
    assert spec is not None and spec.loader is not None
    conftest = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(conftest)
    require_real_data = conftest.require_real_data

    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="real sensor data not found"):
        require_real_data(tmp_path / "absent")
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="CI must provide it"):
        require_real_data(tmp_path / "absent")
    (tmp_path / "here" / "real").mkdir(parents=True)
    assert require_real_data(tmp_path / "here") == (tmp_path / "here").resolve()
