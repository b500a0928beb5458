"""detection_precision: symmetry-aware errors, one real trial, and the summary tables."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from asmteach.core import geometry
from asmteach.core.parts import build_part, load_structure
from asmteach.core.sweep import load_experiment
from asmteach.plugins.detectors.cvfh.experiment import DetectionParams, DetectionPrecision, part_symmetries, pose_errors

import open3d as o3d  # isort: skip  (after asmteach, which loads libusb)

REPO = Path(__file__).resolve().parents[4]
CONFIG = REPO / "configs/experiments/detection_precision.yaml"


def test_pose_errors_are_signed_and_symmetry_aware() -> None:
    T_true = geometry.from_rpy(0.0, 0.0, 0.3, t=[0.4, 0.1, 0.0])
    T_est = geometry.from_rpy(0.0, 0.0, 0.3 + np.radians(2.0), t=[0.4015, 0.0990, 0.0002])
    e = pose_errors(T_est, T_true, [0.0], np.zeros(3))
    assert e["x"] == pytest.approx(1.5, abs=1e-9) and e["y"] == pytest.approx(-1.0, abs=1e-9)
    assert e["z"] == pytest.approx(0.2, abs=1e-9)
    assert e["yaw"] == pytest.approx(2.0, abs=1e-9) and abs(e["roll"]) < 1e-9 and abs(e["pitch"]) < 1e-9
    assert e["rot"] == pytest.approx(2.0, abs=1e-9)
    # A half turn about the vertical through the centre of mass is no error for a C2 placement...
    com = np.array([0.01, 0.0, 0.02])
    c = geometry.transform_points(T_true, com[None])[0]
    turn = geometry.from_rotation(np.eye(3), c) @ geometry.rot_z(np.pi) @ geometry.from_rotation(np.eye(3), -c)
    flipped = turn @ T_true
    assert pose_errors(flipped, T_true, [0.0, np.pi], com)["rot"] < 1e-6
    # ...but is one for a part without that symmetry.
    assert pose_errors(flipped, T_true, [0.0], com)["rot"] == pytest.approx(180.0, abs=1e-6)


def test_part_symmetries_of_library_parts() -> None:
    l_task = load_structure(REPO / "configs/parts/set1/l_corner.yaml")
    l_block, cube = build_part(l_task.part_a), build_part(l_task.part_b)
    slider = build_part(load_structure(REPO / "configs/parts/set1/t_slot.yaml").part_b)
    assert len(part_symmetries(l_block.mesh, l_block.center_of_mass)) == 1  # only the identity
    assert len(part_symmetries(cube.mesh, cube.center_of_mass)) == 24  # the full cube group
    sym = part_symmetries(slider.mesh, slider.center_of_mass)
    assert len(sym) == 2  # identity and the half turn about its long-section axis
    # Every corner of the moved part is a point of the part's surface (the triangulations differ).
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(slider.mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor(np.asarray(slider.mesh.faces, dtype=np.uint32)),
    )
    for S in sym:
        moved = geometry.transform_points(S, slider.mesh.vertices).astype(np.float32)
        assert scene.compute_distance(o3d.core.Tensor(moved)).numpy().max() < 1e-6


def test_experiment_file_validates_and_plans_464_trials() -> None:
    exp, kind = load_experiment(CONFIG)
    assert kind is DetectionPrecision
    assert exp.grid["detector"] == ["cvfh_icp", "fpfh_ransac"] and exp.seed_list() == list(range(232))
    params = DetectionParams.model_validate(exp.params)
    assert sum(len(p.placements) for p in params.parts) == 8  # 8 placements x 4 quarters = 32 cells


@pytest.mark.slow
def test_one_grid_cell_and_the_summary(tmp_path: Path) -> None:
    exp, _ = load_experiment(CONFIG)
    params = DetectionParams.model_validate(
        {**exp.params, "detector_settings": {"views": {"cache_dir": str(tmp_path / "views")}}}
    )
    runner = DetectionPrecision(CONFIG.parent)
    row = runner.run_trial(params, 5, tmp_path)  # placement 2 of the list, quarter 1
    assert row["kind"] == "cell" and row["quarter"] == "near_left" and row["cell"] == "l_block#1"
    assert row["found"], row["reason"]
    assert row["success"] and row["corr_pos"] < 5.0 and row["corr_rot"] < 5.0
    assert row["t_total"] == pytest.approx(row["t_detect"] + row["t_correct"], abs=0.05)
    # Summary over that row plus a made-up random scene and a miss.
    rand = {**row, "kind": "random", "quarter": ""}
    miss = {**rand, "found": False, "success": False, "reason": "not found"}
    for key in [k for k in miss if k.startswith(("rough_", "corr_"))]:
        del miss[key]
    rows = [{"ok": True, "metrics": m} for m in (row, rand, miss)]
    (md_path, csv_path) = runner.summarize(rows, tmp_path)
    md = md_path.read_text()
    assert "## Grid: cvfh_icp" in md and "mean abs" in md and "## Random scenes" in md
    assert "success (<= 5 mm and <= 5 deg) >= 99 %: 50.0 -> NOT met" in md
    assert "l_block#1" in csv_path.read_text()
