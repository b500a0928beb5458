"""``asmteach robot-check`` and the reachability experiment."""

from __future__ import annotations

import numpy as np

from asmteach.core.cli import main
from asmteach.plugins.robots.nextage.build_urdf import URDF_PATH
from asmteach.plugins.robots.nextage.experiment import Reachability, ReachabilityParams, grasp_pose


def test_robot_check_ok_and_bad(tmp_path, capsys) -> None:
    joints = ",".join(f"RARM_JOINT{k}" for k in range(6))
    assert main(["robot-check", str(URDF_PATH), "--joints", joints, "--tcp", "RARM_TCP_Link", "--samples", "5"]) == 0
    out = capsys.readouterr().out
    assert "max TCP difference" in out and "IK round trips: 5/5" in out
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'/><joint name='j' type='hinge'/></robot>")
    assert main(["robot-check", str(bad)]) == 2
    assert "<joint name='j'>: type 'hinge'" in capsys.readouterr().err


def test_grasp_poses_are_rotations() -> None:
    for kind in ("top", "side"):
        T = grasp_pose(kind, 0.4, 0.1, 0.03, 0.7)
        assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3)) and np.linalg.det(T[:3, :3]) > 0
    assert grasp_pose("top", 0, 0, 0, 0)[2, 2] == -1.0
    assert grasp_pose("side", 0, 0, 0, 0)[0, 2] == 1.0


def test_reachability_trial_and_summary(tmp_path) -> None:
    exp = Reachability(tmp_path)
    params = ReachabilityParams(nx=3, ny=3, x_range=(0.3, 0.5), y_range=(0.0, 0.3), yaws_deg=[0.0, 90.0])
    m = exp.run_trial(params, 0, tmp_path)
    assert 0.0 < m["ik_success_rate"] <= 1.0 and len(m["cells"]) == 9
    assert m["max_pos_err_mm"] <= 0.1 and m["max_rot_err_deg"] <= 0.1
    rows = [{"ok": True, "point": {"arm": "left", "grasp": "top"}, "seed": 0, "metrics": m}]
    paths = exp.summarize(rows, tmp_path)
    assert all(p.exists() for p in paths) and any(p.suffix == ".png" for p in paths)
