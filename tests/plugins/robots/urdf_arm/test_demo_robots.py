"""The demo configs with robots we did not write (UR5, Franka Panda, two UR5s) load, and their
kinematics agree with the simulator at home and reach the table where the demo puts the parts."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from asmteach.core.cli import main
from asmteach.core.registry import create
from asmteach.core.run_setup import load_run

ROOT = Path(__file__).resolve().parents[4]
CONFIGS = {"ur5": ["main"], "panda": ["main"], "dual_ur5": ["left", "right"]}


@pytest.fixture(scope="module", params=sorted(CONFIGS))
def demo_robot(request: pytest.FixtureRequest):
    setup = load_run(ROOT / f"configs/demo_{request.param}.yaml")
    with create("robots", setup.cfg.robot.plugin, setup.cfg.robot.settings) as robot:
        yield request.param, setup, robot


def test_config_builds_the_arms(demo_robot) -> None:
    name, setup, robot = demo_robot
    assert robot.arms == CONFIGS[name]
    assert tuple(robot.settings.table_center) == tuple(setup.cfg.table.center)


def test_fk_agrees_with_pybullet_and_ik_round_trips_at_home(demo_robot) -> None:
    _, _, robot = demo_robot
    for arm in robot.arms:
        q = robot.home(arm)
        T = robot.fk(arm, q)
        robot.sim.set_joints(robot.joint_names(arm), q)
        T_pb = robot.sim.link_pose(robot._arm(arm).tcp_link)
        assert np.abs(T - T_pb).max() < 1e-6
        assert T[2, 2] < -0.99  # the hand points down at the table
        assert not robot.in_collision(arm, q[None])[0]
        res = robot.ik(arm, T, q_seed=q + 0.2)
        assert res.success, res.reason
        T_back = robot.fk(arm, res.q)
        assert np.linalg.norm(T_back[:3, 3] - T[:3, 3]) < 1e-4
        assert np.abs(T_back[:3, :3] - T[:3, :3]).max() < 1e-3


def test_every_arm_reaches_down_to_the_goal_and_the_start_region(demo_robot) -> None:
    _, setup, robot = demo_robot
    sc = setup.execution.scene
    points = [(0.40, 0.0)] + [(x, s * y) for x in sc.x_range for y in sc.y_range for s in (-1.0, 1.0)]
    for arm in robot.arms:
        for x, y in points:
            T = np.eye(4)
            T[:3, :3] = np.diag([1.0, -1.0, -1.0])  # approach straight down
            T[:3, 3] = [x, y, setup.table.height + 0.03]
            res = robot.ik(arm, T)
            assert res.success, f"{arm} at ({x}, {y}): {res.reason}"


@pytest.mark.slow
def test_the_ur5_assembles_the_demo_structure(tmp_path: Path) -> None:
    out = tmp_path / "out"
    main(["run", str(ROOT / "configs/demo_ur5.yaml"), "--out", str(out), "--set", "execution.animation=false"])
    report = json.loads((out / "report.json").read_text())
    assert report["success"], report["reason"]
    assert report["metrics"]["achieved_vs_taught_mm"] < 1.0
    assert report["metrics"]["plan_recheck_collisions"] == 0  # PyBullet's re-check agrees with the planner


def test_links_on_one_rigid_body_are_never_checked(demo_robot) -> None:
    name, _, robot = demo_robot
    if name == "ur5":  # the generated gripper sits on the flange that sits on the last wrist link
        assert frozenset(("wrist_3_link", "main_gripper")) in robot.checker.disabled
    on_joint: dict[int, set[str]] = {}
    for g in robot.checker.robot:
        on_joint.setdefault(g.joint, set()).add(g.link)
    for joint, links in on_joint.items():
        if joint >= 0:
            assert all(frozenset((a, b)) in robot.checker.disabled for a in links for b in links if a != b)


def test_the_franka_hand_spec_palm_reaches_as_far_as_the_hand_mesh() -> None:
    import trimesh

    from asmteach.plugins.robots.urdf_arm.compose import source_path

    setup = load_run(ROOT / "configs/demo_panda.yaml")
    with create("robots", "urdf_arm", setup.cfg.robot.settings) as robot:
        q = robot.home("main")
        robot.sim.set_joints(robot.joint_names("main"), q)
        T_tcp_hand = np.linalg.solve(robot.fk("main", q), robot.sim.link_pose("panda_hand"))
        hand = robot.hand
    mesh = trimesh.load(source_path("erd:panda_description/meshes/collision/hand.stl"), force="mesh")
    z = trimesh.transform_points(mesh.vertices, T_tcp_hand)[:, 2]
    front = hand.palm_center[2] + 0.5 * hand.palm_size[2]
    back = hand.palm_center[2] - 0.5 * hand.palm_size[2]
    assert front >= z.max() - 1e-4 and back <= z.min() + 1e-4  # the planner's palm is the whole hand body
