"""A robot package written only on the core's robot contracts is found, plans and runs the whole pipeline."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from asmteach.core import registry
from asmteach.core.interfaces import Obstacle, Robot
from asmteach.core.models import PartSpec, Primitive, SolidSpec, TablePlane, Trajectory
from asmteach.core.parts import build_part
from asmteach.core.robot import World

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = Path(__file__).resolve().parent / "asmteach_gantry"


def _gantry(seed: int = 0):
    return registry.create("robots", "gantry", {}, seed=seed)


def test_the_package_imports_nothing_of_asmteach_but_the_core() -> None:
    for path in sorted(PACKAGE.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else ([node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            )
            for name in names:
                assert not name.startswith("asmteach.") or name.startswith("asmteach.core"), f"{path.name}: {name}"


def test_it_is_discovered_as_a_third_party_robot(gantry_dist: Path) -> None:
    info = {i.name: i for i in registry.discover("robots")}["gantry"]
    assert info.distribution == "asmteach-gantry" and info.error is None
    assert issubclass(info.cls, Robot) and issubclass(info.cls, World)


def test_ik_inverts_fk_anywhere_in_the_workspace(gantry_dist: Path) -> None:
    robot = _gantry()
    lo, hi = robot.joint_limits("main")
    rng = np.random.default_rng(2)
    qs = rng.uniform(lo, hi, size=(200, 6))
    qs[:20, 3:] = rng.normal(0.0, 1e-9, size=(20, 3))  # straight down: the wrist's singular pose
    for q in qs:
        T = robot.fk("main", q)
        res = robot.ik("main", T, q_seed=q + 0.05)
        assert res.success, res.reason
        np.testing.assert_allclose(robot.fk("main", res.q), T, atol=1e-7)  # 1e-7 rad: snapped to the singular pose
    assert not robot.ik("main", robot.fk("main", hi + np.array([1.0, 0, 0, 0, 0, 0]))).success


def test_the_scene_sees_table_obstacles_and_the_held_part(gantry_dist: Path) -> None:
    robot = _gantry()
    q = robot.home("main")
    above = q.copy()
    above[:3] = [0.45, 0.0, 0.2]
    low = above.copy()
    low[2] = 0.05  # the fingertips reach 5 mm below the TCP: still above the table
    into = above.copy()
    into[2] = 0.0
    scene = robot.scene
    assert scene.in_collision("main", np.stack([above, low, into])).tolist() == [False, False, True]
    assert scene.collision_report("main", into)[0][1] == "table"
    block = Obstacle("block", trimesh.creation.box((0.1, 0.1, 0.1)), np.eye(4))
    block.T_world[:3, 3] = [0.45, 0.0, 0.05]
    walled = scene.with_obstacles([block])
    assert walled.in_collision("main", low[None])[0] and not scene.in_collision("main", low[None])[0]
    tips = 0.2 - 0.005  # the fingertips are 5 mm below the TCP
    assert walled.clearance("main", above[None])[0] == pytest.approx(tips - 0.1, abs=1e-6)
    peg = build_part(PartSpec(name="peg", solid=SolidSpec(add=[Primitive(shape="box", size=[0.02, 0.02, 0.1])])))
    T_tcp_peg = np.eye(4)
    T_tcp_peg[2, 3] = 0.05  # the peg sticks out 10 cm below the fingers' tips
    holding = scene.with_attached("main", peg, T_tcp_peg, width=0.02)
    assert holding.in_collision("main", low[None])[0]
    assert not holding.in_collision("main", low[None], ignore=("table",))[0]
    assert robot.scene is scene  # queries and new values leave the robot's scene alone


def test_the_world_executes_grips_and_carries_a_part(gantry_dist: Path) -> None:
    robot = _gantry()
    cube = build_part(PartSpec(name="cube", solid=SolidSpec(add=[Primitive(shape="box", size=[0.03, 0.03, 0.03])])))
    T_cube = np.eye(4)
    T_cube[:3, 3] = [0.4, 0.1, 0.015]
    robot.reset_world(TablePlane(height=0.0), {"cube": (cube, T_cube)})
    q0 = robot.current("main")
    grasp = q0.copy()
    grasp[:3] = [0.4, 0.1, 0.015]
    names = robot.joint_names("main")
    robot.execute(Trajectory(arm="main", joint_names=names, times=[0.0, 1.0], positions=np.stack([q0, grasp])))
    assert robot.grip("main", True, "cube")
    lifted = grasp + np.array([0.1, 0.0, 0.1, 0.5, 0.0, 0.0])
    robot.execute(Trajectory(arm="main", joint_names=names, times=[0.0, 1.0], positions=np.stack([grasp, lifted])))
    np.testing.assert_allclose(robot.part_pose("cube")[:3, 3], [0.5, 0.1, 0.115], atol=1e-9)
    assert "main" in robot.scene.attached
    assert not robot.grip("main", False)
    depth, cloud = robot.sense_depth()
    assert depth.shape == (480, 640) and len(cloud) > 1000
    with pytest.raises(NotImplementedError):
        robot.sense_rgb()


@pytest.mark.slow
def test_the_pipeline_assembles_the_demo_structure_with_the_gantry(gantry_dist: Path, tmp_path: Path) -> None:
    """configs/demo.yaml with the third-party robot: every stage runs and B ends in A (kinematic world)."""
    from asmteach.core.cli import main

    cfg = yaml.safe_load((ROOT / "configs/demo.yaml").read_text())
    cfg["structure"] = str(ROOT / "configs" / cfg["structure"])
    cfg["robot"] = {"plugin": "gantry", "settings": {}}
    cfg["execution"] = {"animation": True}
    path = tmp_path / "gantry.yaml"
    path.write_text(yaml.safe_dump(cfg))
    main(["run", str(path), "--out", str(tmp_path / "out")])
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    stages = {s["stage"]: s for s in report["stages"]}
    assert {"spawn", "detect", "grasps", "plan", "execute", "measure"} <= set(stages), list(stages)
    assert all(s["ok"] for s in report["stages"]), [(s["stage"], s.get("reason")) for s in report["stages"]]
    assert stages["execute"]["details"]["animation"].startswith("not recorded")
    assert report["success"], report.get("reason")
