"""The Nextage's wrist cameras by default: on both hands, beside the gripper body, looking along the approach, the
fingers only a sliver of the image, a part in front of the fingers at the sensor's working range."""

from __future__ import annotations

import numpy as np
import pytest

from asmteach.core.models import TablePlane
from asmteach.plugins.robots.nextage.build_urdf import GRIPPER
from asmteach.plugins.robots.nextage.robot import NextagePyBullet


def test_both_hands_carry_a_camera_looking_along_the_approach_from_beside_the_gripper() -> None:
    robot = NextagePyBullet({})
    assert robot.wrist_cameras() == ["left", "right"]
    for arm in robot.arms:
        cam = robot.wrist_camera(arm)
        T = cam.T_tcp_cam
        assert np.allclose(T[:3, 2], [0.0, 0.0, 1.0])  # optical axis = approach
        assert np.allclose(T[:3, 1], [-1.0, 0.0, 0.0])  # image down = toward the fingers
        # outside the gripper body (x half-thickness) with the D405's 21 mm half-width, at the palm face
        assert T[0, 3] - 0.021 >= 0.5 * GRIPPER.body_size[2]
        assert T[2, 3] == pytest.approx(GRIPPER.body_size[0] - GRIPPER.tcp_depth)
        # a part on the approach axis 0.15-0.30 m beyond the TCP is 0.2-0.4 m from the camera, inside 0.07-0.5 m
        for d in (0.15, 0.30):
            r = np.linalg.norm(np.array([0.0, 0.0, d]) - T[:3, 3])
            assert 0.2 <= r <= 0.4 and cam.sensor.min_range < r < cam.sensor.max_range
    assert NextagePyBullet({"wrist_camera": None}).wrist_cameras() == []


@pytest.mark.slow
def test_the_open_fingers_take_a_sliver_of_the_bottom_rows() -> None:
    with NextagePyBullet({}, seed=1) as robot:
        robot.reset_world(TablePlane(height=0.0), {})
        for arm in robot.arms:
            depth, cloud, T_world_cam = robot.sense_wrist(arm)
            # at home the camera looks straight down at the table 0.22 m below; the fingertips are ~8 cm away
            near = np.isfinite(depth) & (depth < 0.1)
            rows = np.nonzero(near)[0]
            assert 0 < near.mean() < 0.01 and rows.min() >= depth.shape[0] - 30
            assert np.abs(cloud[:, 2]).max() < 0.005  # the cloud: the table only
            assert T_world_cam[2, 3] == pytest.approx(0.22, abs=0.005)
