"""The teaching CLI (render-demo, teach, calibrate) in-process, including bad input (exit code 2)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from asmteach.core.cli import main
from asmteach.plugins.detectors.aruco.calibrate import BoardSpec, make_board
from asmteach.plugins.detectors.aruco.camera import c615_like, save_camera

ROOT = Path(__file__).resolve().parents[4]
PEG = ROOT / "configs/parts/set1/peg_in_hole.yaml"


def _config(tmp: Path, demo: dict | None = None, structure: Path = PEG, name: str = "run.yaml") -> Path:
    p = tmp / name
    p.write_text(yaml.safe_dump({"name": "t", "seed": 1, "structure": str(structure), "demo": demo or {}}))
    return p


@pytest.fixture(scope="module")
def demo_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("demo")
    cfg = _config(tmp, {"frames": 6, "approach_frames": 6, "distance": 0.4, "supersample": 3})
    assert main(["render-demo", str(cfg), "--out", str(tmp / "frames")]) == 0
    return tmp


@pytest.mark.slow
def test_render_demo_writes_frames_camera_and_ground_truth(demo_dir: Path) -> None:
    frames = demo_dir / "frames"
    truth = json.loads((frames / "ground_truth.json").read_text())
    assert len(truth["frames"]) == 12 and (frames / "camera.yaml").is_file()
    assert [f["phase"] for f in truth["frames"]][:6] == ["approach"] * 6
    T_cam_A, T_cam_B = np.array(truth["frames"][-1]["T_cam_A"]), np.array(truth["frames"][-1]["T_cam_B"])
    np.testing.assert_allclose(np.linalg.inv(T_cam_A) @ T_cam_B, truth["T_A_B"], atol=1e-9)
    img = cv2.imread(str(frames / truth["frames"][0]["file"]))
    assert img.shape == (720, 1280, 3)


@pytest.mark.slow
def test_teach_cli_writes_task(demo_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = demo_dir / "task.json"
    cfg = _config(demo_dir)
    assert main(["teach", str(cfg), "--frames", str(demo_dir / "frames"), "--out", str(out)]) == 0
    task = json.loads(out.read_text())
    truth = json.loads((demo_dir / "frames" / "ground_truth.json").read_text())
    assert np.abs(np.array(task["T_A_B"])[:3, 3] - np.array(truth["T_A_B"])[:3, 3]).max() < 1e-3
    assert task["evidence"]["frames_total"] == 12
    # The same frames as a video file.
    video = demo_dir / "demo.avi"
    w = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (1280, 720))
    for f in truth["frames"]:
        w.write(cv2.imread(str(demo_dir / "frames" / f["file"])))
    w.release()
    cam = demo_dir / "frames" / "camera.yaml"
    assert main(["teach", str(cfg), "--frames", str(video), "--camera", str(cam), "--out", str(out)]) == 0


def _err(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    assert main(argv) == 2
    return capsys.readouterr().err


def test_bad_inputs_exit_2_with_clear_message(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = _config(tmp_path)
    blank = tmp_path / "blank"
    blank.mkdir()
    for i in range(4):
        cv2.imwrite(str(blank / f"f{i}.png"), np.full((720, 1280, 3), 128, np.uint8))
    out = str(tmp_path / "t.json")
    msg = _err(["teach", str(cfg), "--frames", str(blank), "--out", out], capsys)
    assert "no marker of part 'holed_block' (ids [0, 1, 2]" in msg
    small = tmp_path / "small"
    small.mkdir()
    cv2.imwrite(str(small / "f.png"), np.zeros((480, 640, 3), np.uint8))
    assert "frame 0 is 640x480 pixels but the camera intrinsics are for 1280x720" in _err(
        ["teach", str(cfg), "--frames", str(small), "--out", out], capsys
    )
    bad_video = tmp_path / "broken.mp4"
    bad_video.write_bytes(b"not a video")
    assert "cannot open the video" in _err(["teach", str(cfg), "--frames", str(bad_video), "--out", out], capsys)
    # A structure with an unknown dictionary, and one with a marker id on both parts.
    raw = yaml.safe_load(PEG.read_text())
    raw["part_a"]["markers"][0]["dictionary"] = "DICT_4X4_51"
    (tmp_path / "dict.yaml").write_text(yaml.safe_dump(raw))
    assert "unknown ArUco dictionary 'DICT_4X4_51'" in _err(
        [
            "teach",
            str(_config(tmp_path, structure=tmp_path / "dict.yaml", name="c2.yaml")),
            "--frames",
            str(blank),
            "--out",
            out,
        ],
        capsys,
    )
    raw = yaml.safe_load(PEG.read_text())
    raw["part_b"]["markers"][0]["id"] = 1
    (tmp_path / "dup.yaml").write_text(yaml.safe_dump(raw))
    assert "marker ids [1] are used on both" in _err(
        [
            "teach",
            str(_config(tmp_path, structure=tmp_path / "dup.yaml", name="c3.yaml")),
            "--frames",
            str(blank),
            "--out",
            out,
        ],
        capsys,
    )
    assert "demo.frame: unknown key" in _err(
        ["render-demo", str(_config(tmp_path, {"frame": 3}, name="c4.yaml")), "--out", str(tmp_path / "o")], capsys
    )


@pytest.mark.slow
def test_too_few_frames_says_how_many(demo_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    few = tmp_path / "few"
    few.mkdir()
    truth = json.loads((demo_dir / "frames" / "ground_truth.json").read_text())
    for f in truth["frames"][-2:]:
        (few / f["file"]).write_bytes((demo_dir / "frames" / f["file"]).read_bytes())
    msg = _err(["teach", str(_config(tmp_path)), "--frames", str(few), "--out", str(tmp_path / "t.json")], capsys)
    assert "in only 2 of 2 frame(s); at least 3 are needed" in msg


def _board_images(K: np.ndarray, dist: np.ndarray, spec: BoardSpec, n: int, seed: int) -> list[np.ndarray]:
    """Board images rendered by a homography at 4x resolution, area-downsampled (anti-aliased)."""
    board = make_board(spec)
    px_per_m = 4000.0
    w_m, h_m = spec.squares_x * spec.square, spec.squares_y * spec.square
    tex = board.generateImage((int(w_m * px_per_m), int(h_m * px_per_m)), marginSize=0, borderBits=1)
    rng = np.random.default_rng(seed)
    S = 4
    Khi = K.copy()
    Khi[:2] *= S
    Khi[0, 2] = S * K[0, 2] + (S - 1) / 2
    Khi[1, 2] = S * K[1, 2] + (S - 1) / 2
    imgs = []
    for _ in range(n):
        # Board frame: x along the texture's columns, y along its rows (down), z away from the camera.
        R, _ = cv2.Rodrigues(rng.uniform(-0.45, 0.45, 3))
        centre = np.array([rng.uniform(-0.06, 0.06), rng.uniform(-0.04, 0.04), rng.uniform(0.45, 0.6)])
        t = centre - R @ np.array([w_m / 2, h_m / 2, 0.0])
        # Board point (x, y) metres = texture pixel (x, y) * 1/px_per_m; plane z = 0.
        A = np.diag([1 / px_per_m, 1 / px_per_m, 1.0])
        H = Khi @ np.column_stack([R[:, 0], R[:, 1], t]) @ A
        # Texture pixel centres are at integer coordinates + 0.5 in metric terms.
        H = H @ np.array([[1, 0, 0.5], [0, 1, 0.5], [0, 0, 1]])
        hi = cv2.warpPerspective(tex, H, (1280 * S, 720 * S), flags=cv2.INTER_AREA, borderValue=200)
        img = cv2.resize(hi, (1280, 720), interpolation=cv2.INTER_AREA)
        imgs.append(cv2.cvtColor(img, cv2.COLOR_GRAY2BGR))
    return imgs


@pytest.mark.slow
def test_calibrate_recovers_known_intrinsics(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cam = c615_like()
    spec = BoardSpec()
    folder = tmp_path / "board"
    folder.mkdir()
    for i, img in enumerate(_board_images(cam.K, cam.dist_array, spec, 12, seed=2)):
        cv2.imwrite(str(folder / f"b{i:02d}.png"), img)
    out = tmp_path / "camera.yaml"
    assert main(["calibrate", "--images", str(folder), "--out", str(out)]) == 0
    from asmteach.plugins.detectors.aruco.camera import load_camera

    got = load_camera(out)
    assert abs(got.K[0, 0] / cam.K[0, 0] - 1) < 0.01 and abs(got.K[1, 1] / cam.K[1, 1] - 1) < 0.01
    assert abs(got.K[0, 2] - cam.K[0, 2]) < 4 and abs(got.K[1, 2] - cam.K[1, 2]) < 4
    save_camera(tmp_path / "again.yaml", got)
    np.testing.assert_allclose(load_camera(tmp_path / "again.yaml").K, got.K, rtol=1e-8)
