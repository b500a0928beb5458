"""The one loader of a run (core/run_setup): what `validate` accepts is what `run` starts from."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from asmteach.core.config import load_run_config
from asmteach.core.errors import UserError
from asmteach.core.run_setup import load_run, prepare_run

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "configs/demo.yaml"


def _config(tmp: Path, **keys: object) -> Path:
    data = {"name": "t", "seed": 1, "structure": str(ROOT / "configs/parts/set1/peg_in_hole.yaml"), **keys}
    path = tmp / "run.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_the_demo_loads_whole_and_hands_its_table_to_the_robot() -> None:
    setup = load_run(DEMO)
    st = setup.cfg.robot.settings
    assert st["table_center"] == [0.45, 0.0] and st["table_size"] == [0.6, 1.2]
    assert "table_height" not in st  # 0 is the robot's own default: nothing to hand over
    assert setup.table_center == (0.45, 0.0) and setup.table_size == (0.6, 1.2)
    assert setup.part_a.name == "holed_block" and setup.part_b.name == "round_peg"
    assert setup.part_a.mesh.is_watertight and setup.part_b.mesh.is_watertight
    assert setup.demo is not None and setup.demo.frames == 30  # the teacher's own model of `demo`
    assert setup.execution.animation_fps == 2.0
    assert "holed_block" in setup.summary()


def test_the_config_handed_in_is_not_changed() -> None:
    cfg = load_run_config(DEMO)
    before = cfg.model_dump(mode="json")
    setup = prepare_run(cfg)
    assert cfg.model_dump(mode="json") == before
    assert setup.cfg.robot.settings != cfg.robot.settings


def test_a_table_height_reaches_the_robot(tmp_path: Path) -> None:
    setup = load_run(_config(tmp_path, table={"height": 0.1}))
    assert setup.cfg.robot.settings["table_height"] == 0.1 and setup.table.height == 0.1


def test_without_a_table_the_robot_keeps_its_own(tmp_path: Path) -> None:
    setup = load_run(_config(tmp_path))
    assert "table_center" not in setup.cfg.robot.settings
    assert setup.table_center == (0.45, 0.0)  # the Nextage plugin's default


def test_a_robot_without_a_table_refuses_a_given_one(tmp_path: Path, toy_dist: Path) -> None:
    cfg = _config(
        tmp_path, teacher={"plugin": "toy_teacher"}, robot={"plugin": "toy_robot"}, table={"center": [0.4, 0.0]}
    )
    with pytest.raises(UserError, match=r"table\.center: the robot plugin 'toy_robot' has no table"):
        load_run(cfg)


def test_a_teacher_without_demo_settings_has_no_demo_and_refuses_one(tmp_path: Path, toy_dist: Path) -> None:
    setup = load_run(_config(tmp_path, teacher={"plugin": "toy_teacher"}))
    assert setup.demo is None
    with pytest.raises(UserError, match=r"demo: the teacher plugin 'toy_teacher' takes no demo settings"):
        load_run(_config(tmp_path, teacher={"plugin": "toy_teacher"}, demo={"anything": 1}))


def test_the_table_left_out_is_none_and_the_robot_table_is_the_runs(tmp_path: Path) -> None:
    """One owner per number: an unwritten centre/size is None in the config, the robot's value in the run."""
    cfg = load_run_config(_config(tmp_path))
    assert cfg.table.center is None and cfg.table.size is None
    setup = prepare_run(cfg)
    assert setup.table_size == (0.6, 1.2) and setup.table.height == cfg.table.height == 0.0


def test_the_execution_section_is_typed(tmp_path: Path) -> None:
    cfg = load_run_config(_config(tmp_path, execution={"animation": False, "scene": {"x_range": [0.3, 0.4]}}))
    assert cfg.execution.animation is False and cfg.execution.scene.x_range == (0.3, 0.4)
    assert cfg.execution.depth_frames == 4  # the default, from the one model


def test_paths_are_relative_to_the_file_that_names_them(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "cfg").mkdir()
    structure = yaml.safe_load((ROOT / "configs/parts/set1/peg_in_hole.yaml").read_text())
    (tmp_path / "cfg" / "s.yaml").write_text(yaml.safe_dump(structure))
    (tmp_path / "cfg" / "cam.yaml").write_text((ROOT / "configs/cameras/c615.yaml").read_text())
    cfg = tmp_path / "cfg" / "run.yaml"
    cfg.write_text(yaml.safe_dump({"name": "t", "structure": "s.yaml", "camera": "cam.yaml"}))
    monkeypatch.chdir(tmp_path)  # not the config's folder
    setup = load_run(cfg)
    assert setup.camera_file == (tmp_path / "cfg" / "cam.yaml").resolve()


def test_errors_of_the_loader_name_the_config_file(tmp_path: Path) -> None:
    cfg = _config(tmp_path, execution={"scene": {"x_range": [0.5, 0.1]}})
    with pytest.raises(UserError) as info:
        load_run(cfg)
    assert str(info.value).startswith(f"{cfg}: execution.scene.x_range")


def test_run_with_bad_input_writes_nothing(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from asmteach.core.cli import main

    out = tmp_path / "out"
    assert main(["run", str(_config(tmp_path, demo={"orientation": 7})), "--out", str(out)]) == 2
    assert not out.exists() or not any(out.iterdir())
    assert "demo.orientation" in capsys.readouterr().err


@pytest.mark.slow
def test_kill_9_mid_render_leaves_the_older_results_and_the_next_run_replaces_them(tmp_path: Path) -> None:
    """render-demo writes through the same staging folder as run: a kill -9 mid-way mixes nothing in."""
    import json
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "out"
    out.mkdir()
    (out / "ground_truth.json").write_text(json.dumps({"structure": "set1_peg_in_hole", "old": True}))
    (out / "frame_0099.jpg").write_text("an older demonstration's frame")
    slow = _config(tmp_path, demo={"frames": 400, "approach_frames": 0, "supersample": 1})
    proc = subprocess.Popen(
        [sys.executable, "-m", "asmteach.core.cli", "render-demo", str(slow), "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None and not list(out.glob(".partial-*/frame_*")):
        time.sleep(0.05)
    assert proc.poll() is None, "render-demo ended before it could be killed"
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == [
        "frame_0099.jpg",
        "ground_truth.json",
    ]
    assert json.loads((out / "ground_truth.json").read_text())["old"]

    quick = tmp_path / "quick"
    quick.mkdir()
    cfg = _config(quick, demo={"frames": 2, "approach_frames": 0, "supersample": 1})
    from asmteach.core.cli import main

    assert main(["render-demo", str(cfg), "--out", str(out)]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == ["camera.yaml", "frame_0000.jpg", "frame_0001.jpg", "ground_truth.json"]  # nothing stale
