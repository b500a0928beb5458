"""The simulated Nextage: holding a box when lifted, trajectory checks, part poses, cameras."""

from __future__ import annotations

import numpy as np
import pytest

from asmteach.core.errors import UserError
from asmteach.core.models import PartSpec, Primitive, SolidSpec, TablePlane, Trajectory
from asmteach.core.parts import build_part
from asmteach.plugins.robots.nextage.robot import NextagePyBullet


def _box(name: str, size: float) -> object:
    return build_part(PartSpec(name=name, solid=SolidSpec(add=[Primitive(shape="box", size=[size] * 3)])))


def _move(robot: NextagePyBullet, arm: str, q_to: np.ndarray, seconds: float = 1.5) -> None:
    q0 = robot.current(arm)
    s = np.linspace(0.0, 1.0, 16)
    pos = q0[None] + s[:, None] * (q_to - q0)[None]
    robot.execute(Trajectory(arm=arm, joint_names=robot.joint_names(arm), times=(s * seconds).tolist(), positions=pos))


@pytest.mark.slow
def test_gripper_holds_a_box_when_lifted() -> None:
    with NextagePyBullet({}) as robot:
        T_box = np.eye(4)
        T_box[:3, 3] = [0.38, 0.22, 0.02]
        robot.reset_world(TablePlane(height=0.0), {"box": (_box("box", 0.04), T_box)})
        robot.sim.step(60)
        rest = robot.part_pose("box")
        assert np.allclose(rest[:3, 3], T_box[:3, 3], atol=3e-3)
        grasp = np.eye(4)
        grasp[:3, :3] = np.diag([1.0, -1.0, -1.0])  # approach down, jaw along world -y
        grasp[:3, 3] = rest[:3, 3]
        above = grasp.copy()
        above[2, 3] += 0.12
        ik_above = robot.ik("left", above)
        ik_grasp = robot.ik("left", grasp, ik_above.q)
        assert ik_above.success and ik_grasp.success
        _move(robot, "left", ik_above.q)
        _move(robot, "left", ik_grasp.q)
        assert robot.grip("left", True, "box")
        _move(robot, "left", ik_above.q)
        lifted = robot.part_pose("box")
        assert lifted[2, 3] > rest[2, 3] + 0.1  # it came up with the hand
        T_tcp = robot.fk("left", robot.current("left"))
        assert np.linalg.norm(lifted[:3, 3] - T_tcp[:3, 3]) < 0.01  # and did not slip
        assert robot.grip("left", False) is False
        robot.sim.step(240)
        assert robot.part_pose("box")[2, 3] < 0.03  # released: it fell back to the table


def test_trajectory_checks() -> None:
    with NextagePyBullet({}) as robot:
        names = robot.joint_names("left")
        q0 = robot.home("left")
        jump = np.stack([q0, q0 + np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0])])
        with pytest.raises(UserError, match=r"jumps: LARM_JOINT3 moves 1\.000 rad in 0\.010 s"):
            robot.check_trajectory(Trajectory(arm="left", joint_names=names, times=[0.0, 0.01], positions=jump))
        far = q0 + 0.3
        with pytest.raises(UserError, match=r"starts .* rad away"):
            robot.check_trajectory(Trajectory(arm="left", joint_names=names, times=[0.0], positions=far[None]))
        bad = q0.copy()
        bad[2] = 0.4
        with pytest.raises(UserError, match="outside its limits"):
            robot.check_trajectory(Trajectory(arm="left", joint_names=names, times=[0.0, 5.0],
                                              positions=np.stack([q0, bad])))
        with pytest.raises(UserError, match="expected"):
            robot.check_trajectory(Trajectory(arm="left", joint_names=names[::-1], times=[0.0], positions=q0[None]))


def test_execute_reaches_the_goal_under_speed_limits() -> None:
    with NextagePyBullet({"speed_scale": 0.5}) as robot:
        robot.reset_world(TablePlane(height=0.0), {})
        q0 = robot.home("right")
        goal = q0 + np.array([0.2, -0.2, 0.1, 0.0, 0.1, 0.3])
        _move(robot, "right", goal, seconds=1.0)
        assert np.allclose(robot.current("right"), goal, atol=5e-3)


@pytest.mark.slow
def test_cameras_see_the_table_and_part() -> None:
    pytest.importorskip("asmteach.plugins.detectors.depth_camera")
    with NextagePyBullet({}) as robot:
        T_box = np.eye(4)
        T_box[:3, 3] = [0.45, 0.0, 0.03]
        robot.reset_world(TablePlane(height=0.0), {"box": (_box("box", 0.06), T_box)})
        depth, cloud = robot.sense_depth()
        assert depth.shape == (480, 640) and cloud.shape[1] == 3 and len(cloud) > 10000
        near_box = np.linalg.norm(cloud[:, :2] - [0.45, 0.0], axis=1) < 0.02
        assert np.median(cloud[near_box, 2]) == pytest.approx(0.06, abs=0.01)  # the top face of the box
        rgb = robot.sense_rgb()
        assert rgb.shape == (480, 640, 3) and rgb.std() > 5
