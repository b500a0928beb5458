"""`asmteach run`: bad input is one line with exit 2; a whole simulated run writes its report."""

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from asmteach.core.cli import main
from asmteach.core.config import SceneSettings
from asmteach.core.parts import build_part, load_structure
from asmteach.core.scene import random_start_poses

ROOT = Path(__file__).resolve().parents[3]
STRUCTURE = ROOT / "configs/parts/set1/peg_in_hole.yaml"


def _config(tmp_path: Path, **extra) -> Path:
    cfg = {"name": "t", "seed": 3, "structure": str(STRUCTURE), **extra}
    path = tmp_path / "run.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def test_bad_execution_key_is_one_line_and_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    cfg = _config(tmp_path, execution={"animaton": False})
    assert main(["run", str(cfg), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "execution.animaton" in err[0]


def test_bad_override_is_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["run", str(_config(tmp_path)), "--out", str(tmp_path / "o"), "--set", "seed"]) == 2
    assert "KEY=VALUE" in capsys.readouterr().err


@pytest.mark.parametrize(("given", "means"), [(True, "ambiguous"), (False, "never"), ("always", "always")])
def test_look_again_takes_the_old_yes_no_too(given: object, means: str) -> None:
    from asmteach.core.config import ExecutionSettings

    assert ExecutionSettings.model_validate({"look_again": given}).look_again == means


def test_look_again_names_its_choices(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    cfg = _config(tmp_path, execution={"look_again": "sometimes"})
    assert main(["run", str(cfg), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "execution.look_again" in err[0] and "always" in err[0]


def test_nearest_symmetric_pose_is_the_twin_closest_to_the_reference() -> None:
    """A square peg seen turned 90 deg about its axis (plus noise) is the same solid as the planned pose."""
    from asmteach.core import geometry
    from asmteach.core.pose_error import nearest_symmetric, pose_error
    from asmteach.core.symmetry import part_symmetries

    peg = build_part(load_structure(STRUCTURE).part_b)
    syms = part_symmetries(peg.mesh, np.asarray(peg.center_of_mass))
    T_ref = geometry.from_rpy(0.0, 0.0, 0.4, t=[0.4, 0.0, 0.02])
    seen = T_ref @ geometry.from_rpy(0.0, 0.0, np.radians(90.5), t=[0.0003, 0.0, 0.0])
    assert pose_error(seen, T_ref).angle_deg > 90.0
    near = nearest_symmetric(seen, T_ref, syms)
    assert pose_error(near, T_ref).angle_deg == pytest.approx(0.5, abs=1e-6)
    np.testing.assert_allclose(
        geometry.transform_points(near, peg.mesh.vertices).mean(0),
        geometry.transform_points(seen, peg.mesh.vertices).mean(0),
        atol=1e-9,
    )


def test_random_start_poses_rest_on_the_table_apart_and_are_seeded() -> None:
    task = load_structure(STRUCTURE)
    parts = [build_part(task.part_a), build_part(task.part_b)]
    s = SceneSettings()
    Ts = random_start_poses(parts, 0.2, s, np.random.default_rng(5))
    again = random_start_poses(parts, 0.2, s, np.random.default_rng(5))
    for T, T2, part in zip(Ts, again, parts, strict=True):
        np.testing.assert_array_equal(T, T2)
        low = (part.mesh.vertices @ T[:3, :3].T + T[:3, 3])[:, 2].min()
        assert low == pytest.approx(0.2, abs=1e-9)
        assert s.x_range[0] <= T[0, 3] <= s.x_range[1] + 0.05
    assert np.sign(Ts[0][1, 3]) == -np.sign(Ts[1][1, 3])


@pytest.mark.slow
def test_whole_run_goes_through_every_stage_and_writes_its_report(tmp_path: Path) -> None:
    """Teach -> spawn -> detect -> grasps -> plan -> execute -> measure on the simulated Nextage.

    Whether the parts end assembled is measured (metrics, exit code) but not
    asserted here: the end-to-end success rate is an experiment, not a unit test.
    """
    cfg = _config(
        tmp_path,
        motion_planner={"plugin": "trrt"},
        robot={"plugin": "nextage_pybullet", "settings": {"ik": {"max_starts": 4}, "start_tolerance": 0.06}},
        execution={"animation_fps": 1.0},
    )
    out = tmp_path / "out"
    code = main(["run", str(cfg), "--out", str(out)])
    report = json.loads((out / "report.json").read_text())
    stages = {s["stage"]: s for s in report["stages"]}
    for name in ("teach", "spawn", "detect", "grasps", "plan", "execute"):
        assert stages[name]["ok"], (name, stages[name]["reason"])
    assert "measure" in stages
    assert code == (0 if report["success"] else 1)
    m = report["metrics"]
    assert m["teach_position_mm"] < 1.0 and m["teach_angle_deg"] < 1.0
    assert all(m[f"detect_{p}_surface_mm"] < 3.0 for p in ("holed_block", "round_peg"))
    assert m["a_goal_error_mm"] < 5.0  # A was carried to its goal
    html = (out / "report.html").read_text()
    assert "data:image/png;base64" in html and "http://" not in html and "https://" not in html
    for name in ("task.json", "plan.json", "detection.png", "execution.gif", "regrasp_graph_A.png"):
        assert (out / name).is_file(), name


@pytest.mark.slow
def test_an_ambiguous_block_is_looked_at_again_once_placed_and_the_assembly_planned_again(tmp_path: Path) -> None:
    """The demo's seed 12 lays the holed block on its side with the hole away from the camera.

    The detector reports the turned-over twin as ambiguous and happens to pick
    it; once A stands at its goal the camera sees its top, finds it upside down
    (40 mm / 180 deg from the goal), and the assembly is planned again from there.
    """
    out = tmp_path / "out"
    # one depth frame, as when this scene was found: with four, the detector happens to pick the right twin
    # no wrist-camera look at detect: it settles the twin there (core/pipeline/active_look), and this test is
    # about the look at the goal. ICP onto the whole model, as when this scene was found: onto the surface the
    # camera sees (refine.visible_icp, the default since session 17) the provisional pick is the right twin
    main(
        [
            "run",
            str(ROOT / "configs/demo.yaml"),
            "--out",
            str(out),
            "--set",
            "seed=12",
            "--set",
            "execution.animation=false",
            "--set",
            "execution.depth_frames=1",
            "--set",
            "execution.look_closer=0",
            "--set",
            "detector.settings.refine.visible_icp=false",
        ]
    )
    report = json.loads((out / "report.json").read_text())
    block = next(d for d in report["detections"] if d["part"] == "holed_block")
    assert block["details"]["ambiguous"]
    stages = {s["stage"]: s for s in report["stages"]}
    assert stages["execute_a"]["ok"] and stages["look_again"]["ok"], report["reason"]
    look = stages["look_again"]["details"]
    assert look["replanned"] and look["a_vs_goal"]["angle_deg"] > 170.0
    assert (out / "plan_again.json").is_file()
    assert report["success"], report["reason"]


@pytest.mark.slow
def test_a_block_put_down_a_millimetre_off_is_seen_and_the_peg_aimed_at_it(tmp_path: Path) -> None:
    """The demo's seed 38: the lying block's yaw is detected 2.9 deg off, so it is set down 1 mm from its goal,
    twice the hole's radial clearance. Seen there, the peg's insertion is planned again into it (issue 9's jam)."""
    out = tmp_path / "out"
    # one depth frame, as when this scene was found: with four, the yaw is detected well enough
    main(
        [
            "run",
            str(ROOT / "configs/demo.yaml"),
            "--out",
            str(out),
            "--set",
            "seed=38",
            "--set",
            "execution.animation=false",
            "--set",
            "execution.depth_frames=1",
        ]
    )
    report = json.loads((out / "report.json").read_text())
    look = next(s for s in report["stages"] if s["stage"] == "look_again")["details"]
    assert look["a_true_vs_goal"]["position_mm"] > 0.8  # A really is off (the simulator's truth)
    assert look["reaimed"] and not look["replanned"]
    plan_again = json.loads((out / "plan_again.json").read_text())
    assert {seg["part"] for seg in plan_again["segments"]} == {"round_peg"}
    assert report["success"], report["reason"]
    assert report["metrics"]["achieved_vs_taught_mm"] < 0.5


def test_a_look_stacks_the_clouds_of_several_depth_frames() -> None:
    from asmteach.core.config import ExecutionSettings
    from asmteach.core.pipeline.detect import sense

    class Camera:
        calls = 0

        def sense_depth(self) -> tuple[np.ndarray, np.ndarray]:
            self.calls += 1
            return np.full((4, 4), float(self.calls)), np.full((10, 3), float(self.calls))

        def camera_pose(self) -> np.ndarray:
            return np.eye(4)

    cam = Camera()
    depth, cloud, eye = sense(cam, ExecutionSettings().depth_frames)
    assert cam.calls == 4 and cloud.shape == (40, 3)
    assert sorted(set(cloud[:, 0])) == [1.0, 2.0, 3.0, 4.0]  # every frame's own points
    assert np.all(depth == 1.0) and np.all(eye == 0.0)
    assert sense(Camera(), 1)[1].shape == (10, 3)
