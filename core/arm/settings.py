"""Settings every simulated arm robot shares (:class:`ArmRobotSettings`) and where its cameras sit.

The robot plugins that build on :class:`~asmteach.core.arm.robot.ArmRobot`
(the Nextage, ``urdf_arm``) subclass :class:`ArmRobotSettings` with their own keys.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field

from asmteach.core.arm.dls_ik import IKSettings
from asmteach.core.arm.sim import POSITION_GAIN
from asmteach.core.models import StrictModel

__all__ = ["ArmRobotSettings", "CameraMount", "WristCameraMount"]


class CameraMount(StrictModel):
    """Where the simulated depth/RGB camera sits (world x, y; z above the table top; metres)."""

    eye: tuple[float, float, float] = Field((1.05, 0.0, 0.75), description="camera position; z above the table top")
    target: tuple[float, float, float] = Field((0.45, 0.0, 0.0), description="point looked at; z above the table")


class WristCameraMount(StrictModel):
    """A depth camera on the hand of some arms: its pose ``T_tcp_cam`` in the TCP frame (metres, degrees) and its
    sensor model.

    ``T_tcp_cam`` is the camera's OpenCV frame (z forward, y down) in the TCP frame
    (:class:`~asmteach.core.models.HandSpec`: z = approach, y = jaw axis), built as
    ``from_rpy(radians(rpy_deg), xyz)``. The camera is not a collision body, neither for the
    planner nor in the simulation, and the fixed cameras do not see it.
    """

    arms: list[str] = Field(description="the arms whose hand carries the camera")
    xyz: tuple[float, float, float] = Field(description="camera centre in the TCP frame, metres")
    rpy_deg: tuple[float, float, float] = Field(
        description="roll, pitch, yaw (degrees, fixed axes x-y-z) of the camera frame in the TCP frame"
    )
    sensor: Literal["wrist_stereo", "kinect"] = Field(
        "wrist_stereo",
        description="the sensor model: KinectSettings.wrist_stereo() (a RealSense D405-like stereo camera) or "
        "KinectSettings() (the cell's Kinect v1)",
    )
    sensor_overrides: dict[str, Any] = Field(
        default_factory=dict, description="KinectSettings fields that replace the preset's, e.g. {max_range: 0.4}"
    )


class ArmRobotSettings(StrictModel):
    """Settings every simulated arm robot shares (metres, radians, seconds, newtons)."""

    table_height: float = Field(0.0, ge=-2.0, le=2.0, description="world z of the table top, metres")
    table_center: tuple[float, float] = Field((0.45, 0.0), description="table centre x, y (world), metres")
    table_size: tuple[float, float] = Field((0.6, 1.2), description="table extent along x, y, metres")
    gui: bool = Field(False, description="open PyBullet's window (needs a display)")
    ik: IKSettings = Field(default_factory=IKSettings, description="the inverse-kinematics solver")
    speed_scale: float = Field(1.0, gt=0.0, le=1.0, description="fraction of each joint's speed limit used")
    jump_tolerance: float = Field(1.05, ge=1.0, description="a trajectory may exceed the speed limits by this factor")
    start_tolerance: float = Field(0.02, gt=0.0, description="radians between the current q and a trajectory's start")
    grip_force: float = Field(40.0, gt=0.0, description="finger force, newtons")
    time_step: float = Field(1.0 / 240.0, gt=0.0, le=0.01, description="physics step, seconds")
    position_gain: float = Field(
        POSITION_GAIN,
        gt=0.0,
        le=1.0,
        description="positionGain of the simulated joint servos; PyBullet's default 0.1 leaves ~1 mrad steady error",
    )
    camera: CameraMount = Field(default_factory=CameraMount, description="where the simulated camera sits")
    second_camera: CameraMount | None = Field(
        None,
        description="a second depth camera (same model, its own noise), e.g. {eye: [0.45, -0.8, 0.6], target: "
        "[0.45, 0, 0]} beside the table: a detection the first view leaves ambiguous is judged on both views. Off by "
        "default: in the corpus benchmark that side camera settled 19 of 63 ambiguous scenes but reported 2 wrong "
        "poses (docs/results/any_cad_part.md, Session 15); null: one camera",
    )
    wrist_camera: WristCameraMount | None = Field(
        None, description="a depth camera on the hands of some arms (World.sense_wrist); null: none"
    )
