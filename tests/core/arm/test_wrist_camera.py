"""The depth camera on a hand (World.wrist_camera / sense_wrist) of the simulated arm robot: where it looks after
the arm moved, what it sees, that it never sees the robot in its cloud, its own seeded noise, and that the fixed
camera's frames are the same with and without it."""

from __future__ import annotations

import numpy as np
import pytest

from asmteach.core.errors import UserError
from asmteach.core.models import PartSpec, Primitive, SolidSpec, TablePlane, Trajectory
from asmteach.core.parts import build_part
from asmteach.core.robot import World, WristCamera

BOX = 0.04  # edge of the box part, metres


def _robot(settings: dict | None = None, seed: int = 0) -> object:
    from asmteach.plugins.robots.nextage.robot import NextagePyBullet

    return NextagePyBullet(settings or {}, seed=seed)


def _move_left_hand_down_to(robot: object, xyz: tuple[float, float, float]) -> np.ndarray:
    """Execute a straight joint move of the left arm to the hand pointing down at ``xyz`` (the home's orientation)."""
    arm = "left"
    T = robot.fk(arm, robot.current(arm))
    T[:3, 3] = xyz
    res = robot.ik(arm, T)
    assert res.success and not res.flipped
    q0 = robot.current(arm)
    seconds = float(np.max(np.abs(res.q - q0) / robot.speed_limits(arm))) * 1.5 + 0.2
    times = np.linspace(0.0, seconds, 20)
    path = q0 + (res.q - q0) * (times / seconds)[:, None]
    robot.execute(Trajectory(arm=arm, joint_names=robot.joint_names(arm), times=times.tolist(), positions=path))
    return robot.current(arm)


def _box_under_camera(robot: object, arm: str) -> np.ndarray:
    """Reset the world with the box on the table right under ``arm``'s wrist camera; returns T_world_box."""
    box = build_part(PartSpec(name="box", solid=SolidSpec(add=[Primitive(shape="box", size=[BOX] * 3)])))
    T_cam = robot.fk(arm, robot.current(arm)) @ robot.wrist_camera(arm).T_tcp_cam
    T_box = np.eye(4)
    T_box[:3, 3] = [T_cam[0, 3], T_cam[1, 3], 0.5 * BOX]
    q_left = robot.current("left")
    robot.reset_world(TablePlane(height=0.0), {"box": (box, T_box)})
    if not np.allclose(q_left, robot.current("left")):  # reset_world sent it home: back over the box
        _move_left_hand_down_to(robot, tuple(robot.fk("left", q_left)[:3, 3]))
    return T_box


@pytest.mark.slow
def test_the_wrist_camera_sees_the_box_below_it_at_its_range_and_no_robot() -> None:
    with _robot(seed=3) as robot:
        assert robot.wrist_cameras() == ["left", "right"]
        robot.reset_world(TablePlane(height=0.0), {})
        q = _move_left_hand_down_to(robot, (0.40, 0.10, 0.22))
        T_box = _box_under_camera(robot, "left")
        cam = robot.wrist_camera("left")
        assert isinstance(cam, WristCamera) and cam.sensor.max_range == 0.5
        depth, cloud, T_world_cam = robot.sense_wrist("left")
        # the pose it reports is fk at the arm's joints now, composed with the mount
        assert np.allclose(T_world_cam, robot.fk("left", robot.current("left")) @ cam.T_tcp_cam, atol=1e-9)
        assert np.allclose(robot.current("left"), q, atol=1e-3)  # the servos end within ~0.1 mrad
        expected = T_world_cam[2, 3] - BOX  # straight down onto the box's top face
        assert 0.15 < expected < 0.35
        h, w = depth.shape
        centre = depth[h // 2 - 10 : h // 2 + 10, w // 2 - 10 : w // 2 + 10]
        sigma = cam.sensor.axial_sigma(expected)
        assert np.isfinite(centre).all() and abs(np.mean(centre) - expected) < max(3 * sigma / 20, 0.0005)
        # the cloud: the box's top and the table, never the fingers or the robot body the image holds
        on_top = np.all(np.abs(cloud[:, :2] - T_box[:2, 3]) < 0.5 * BOX - 0.003, axis=1)
        assert on_top.sum() > 2000 and np.abs(np.median(cloud[on_top, 2]) - BOX) < 0.001
        assert cloud[:, 2].max() < BOX + 0.01
        fingers = depth[h - 20 :, :]  # the fingertips are in the image's bottom rows, ~8 cm away
        assert np.nanmin(fingers) < 0.1


@pytest.mark.slow
def test_wrist_frames_repeat_for_a_seed_and_each_arm_has_its_own_noise() -> None:
    frames = []
    for seed in (5, 5, 6):
        with _robot(seed=seed) as robot:
            robot.reset_world(TablePlane(height=0.0), {})
            _box_under_camera(robot, "left")
            frames.append((robot.sense_wrist("left"), robot.sense_wrist("right")))
    same, again, other = frames
    for arm in (0, 1):
        assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(same[arm], again[arm], strict=True))
        assert not np.array_equal(same[arm][0], other[arm][0], equal_nan=True)
    # each arm draws from its own generator: the right arm's frame is the same without a left frame before it
    with _robot(seed=5) as robot:
        robot.reset_world(TablePlane(height=0.0), {})
        _box_under_camera(robot, "left")
        alone = robot.sense_wrist("right")
    assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(same[1], alone, strict=True))


@pytest.mark.slow
def test_the_fixed_camera_frame_is_the_same_with_and_without_the_wrist_camera() -> None:
    box = build_part(PartSpec(name="box", solid=SolidSpec(add=[Primitive(shape="box", size=[BOX] * 3)])))
    T_box = np.eye(4)
    T_box[:3, 3] = [0.45, 0.0, 0.5 * BOX]
    seen = []
    for settings in ({}, {"wrist_camera": None}):
        with _robot(settings, seed=2) as robot:
            robot.reset_world(TablePlane(height=0.0), {"box": (box, T_box)})
            if robot.wrist_cameras():
                robot.sense_wrist("left")
            seen.append((*robot.sense_depth(), robot.camera_pose()))
    assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(*seen, strict=True))


def test_bad_wrist_camera_settings_are_one_line_errors() -> None:
    mount = {"arms": ["left", "middle"], "xyz": [0.0, 0.0, 0.0], "rpy_deg": [0.0, 0.0, 0.0]}
    with pytest.raises(UserError, match=r"wrist_camera.arms: no arm \['middle'\]"):
        _robot({"wrist_camera": mount})
    robot = _robot({"wrist_camera": {**mount, "arms": ["left"], "sensor_overrides": {"max_range": -1}}})
    assert robot.wrist_cameras() == ["left"]
    with pytest.raises(UserError, match="sensor_overrides: max_range"):
        robot.wrist_camera("left")
    with pytest.raises(UserError, match="'right' has no wrist camera"):
        robot.sense_wrist("right")
    assert _robot({"wrist_camera": None}).wrist_cameras() == []
    kinect = _robot({"wrist_camera": {**mount, "arms": ["right"], "sensor": "kinect"}}).wrist_camera("right")
    assert kinect.sensor.min_range == 0.4 and np.allclose(kinect.T_tcp_cam, np.eye(4))


def test_a_world_without_wrist_cameras_says_so() -> None:
    class Bare(World):
        def reset_world(self, table: object, parts: object) -> None: ...
        def current(self, arm: str) -> np.ndarray: ...
        def execute(self, trajectory: object) -> None: ...
        def grip(self, arm: str, close: bool, part: str | None = None) -> bool: ...
        def part_pose(self, name: str) -> np.ndarray: ...
        def sense_depth(self) -> tuple[np.ndarray, np.ndarray]: ...

    bare = Bare()
    assert bare.wrist_cameras() == []
    for ask in (bare.wrist_camera, bare.sense_wrist):
        with pytest.raises(NotImplementedError, match="no wrist camera"):
            ask("left")
