"""The Kawada NEXTAGE OPEN in PyBullet, with pinocchio kinematics and fcl collision checking.

World frame: z up, metres. The table top is at world z = ``table_height``;
the WAIST (the robot's root: x forward, y left, z up) sits
``waist_above_table`` above it at world x = y = 0 by default, so the table
(x 0.15..0.75 by default) is in front of the robot along +x. With the default
0.17 m the table top is 0.80 m above the floor of the Kawada model (the WAIST
is 0.97 m above it), a little below the fingertips at the upstream init pose.
Give ``base_pose`` to place the WAIST anywhere else.

Model: by default our own primitive-shape URDF (``nextage.urdf``, boxes and
cylinders, fast exact collision checks). ``urdf:`` gives the vendor's
``NextageOpen.urdf`` instead (``package://`` meshes resolved from
``package_paths``), with our gripper on its wrist flanges
(:mod:`asmteach.plugins.robots.nextage.vendor`): same joint and link names,
the vendor's meshes for planning (python-fcl) and simulation (PyBullet).

Arms ``"left"`` and ``"right"``: ``LARM_JOINT0..5`` / ``RARM_JOINT0..5``,
with ``use_chest: true`` preceded by ``CHEST_JOINT0`` (7 DOF; moving the
chest moves both arms). The TCP is ``*ARM_TCP_Link`` of the two-finger
gripper (see :mod:`asmteach.plugins.robots.nextage.hand`). Home is, by
default, a *ready* pose with the hands 0.15 m above the table, pointing down,
behind the workspace as the camera sees it; the upstream init pose
("goInitial") leaves the fingertips 3 cm above the table top, where parts lie.

Wrist cameras: the real NEXTAGE OPEN carries an RGB camera on each hand; we model
a short-range depth camera there instead (:data:`WRIST_CAMERA`, a RealSense
D405-like active stereo sensor), as integrators mount one to look closer than
the cell's Kinect can. It is on both arms by default (``wrist_camera: null``
switches it off) and is not a collision body (a D405 is 42 x 42 x 23 mm).
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field

from asmteach.core import geometry
from asmteach.core.arm.robot import ArmRobot, ArmSpec
from asmteach.core.arm.settings import ArmRobotSettings, WristCameraMount
from asmteach.core.arm.sim_gripper import GripperJoints
from asmteach.core.errors import UserError
from asmteach.core.models import Mat4
from asmteach.plugins.robots.nextage.build_urdf import GRIPPER, URDF_PATH
from asmteach.plugins.robots.nextage.hand import nextage_hand
from asmteach.plugins.robots.nextage.vendor import vendor_urdf

__all__ = ["INIT_POSE", "READY_POSE", "SRDF_DISABLED", "NextagePyBullet"]

INIT_POSE = {
    "left": np.radians([0.6, 0.0, -100.0, -15.2, 9.4, -3.2]),
    "right": np.radians([-0.6, 0.0, -100.0, 15.2, 9.4, 3.2]),
}
"""Upstream init pose ("goInitial", SRDF init_rtm), radians."""

READY_POSE = {
    "left": np.radians([-6.3, 11.1, -141.1, -19.6, 40.0, -6.4]),
    "right": np.radians([6.3, 11.1, -141.1, 19.6, 40.0, 6.4]),
}
"""Hands pointing down 0.15 m above the table at x = 0.25, y = +-0.20 (IK of that pose), radians."""

_PREFIX = {"left": "LARM", "right": "RARM"}


def _srdf_disabled() -> list[tuple[str, str]]:
    """Link pairs never checked: NextageOpen.srdf's Default and Never lists, plus each hand's two fingers."""
    pairs = [("CHEST_JOINT0_Link", "HEAD_JOINT1_Link")]
    for k in range(4):
        pairs += [("HEAD_JOINT0_Link", f"LARM_JOINT{k}_Link"), ("HEAD_JOINT0_Link", f"RARM_JOINT{k}_Link")]
    pairs += [
        ("HEAD_JOINT0_Link", "WAIST"),
        ("HEAD_JOINT1_Link", "LARM_JOINT0_Link"),
        ("HEAD_JOINT1_Link", "RARM_JOINT0_Link"),
        ("HEAD_JOINT1_Link", "WAIST"),
    ]
    for s in ("LARM", "RARM"):
        pairs += [
            (f"{s}_JOINT0_Link", f"{s}_JOINT2_Link"),
            (f"{s}_JOINT0_Link", f"{s}_JOINT3_Link"),
            (f"{s}_JOINT1_Link", f"{s}_JOINT3_Link"),
            (f"{s}_JOINT2_Link", f"{s}_JOINT4_Link"),
            (f"{s}_FINGER0_Link", f"{s}_FINGER1_Link"),
        ]
    pairs += [("LARM_JOINT0_Link", f"RARM_JOINT{k}_Link") for k in range(4)]
    pairs += [("RARM_JOINT0_Link", f"LARM_JOINT{k}_Link") for k in range(1, 4)]
    return pairs


SRDF_DISABLED = _srdf_disabled()

WRIST_CAMERA = WristCameraMount(arms=["left", "right"], xyz=(0.055, 0.0, -0.07), rpy_deg=(0.0, 0.0, 90.0))
"""The wrist depth camera of both arms, in the TCP frame (:mod:`~asmteach.plugins.robots.nextage.hand`).

On the gripper body's +x face (the body is 65 mm thick along x, the camera 42 mm wide: centre 55 mm off the
approach axis), its front flush with the palm face (70 mm behind the TCP), looking along the approach (z) with
the image's down (y) toward the fingers (-x of the TCP). A part the TCP is 0.15-0.30 m from is 0.22-0.37 m from
the camera. The fingertips, 44 mm beside and 87.5 mm in front of it, are 26.7 deg off its axis against a 29 deg
half field of view: they show as two blobs in the image's bottom 22 rows. Not a collision body.
"""


class NextageSettings(ArmRobotSettings):
    """Settings of the simulated Nextage (metres, radians)."""

    waist_above_table: float = Field(0.17, ge=-0.5, le=1.0, description="WAIST height above the table top")
    base_pose: Mat4 | None = Field(None, description="T_world_waist; default: (0, 0, table_height + waist_above_table)")
    use_chest: bool = Field(False, description="arms include CHEST_JOINT0 (7 DOF)")
    home_pose: Literal["ready", "init"] = Field(
        "ready", description="home: hands 0.15 m above the table (ready) or the upstream init pose"
    )
    urdf: str | None = Field(
        None,
        description="the vendor's NextageOpen.urdf (nextage_description) instead of our primitive model; "
        "relative paths from the working directory; our gripper goes on its wrist flanges",
    )
    wrist_camera: WristCameraMount | None = Field(
        default_factory=lambda: WRIST_CAMERA.model_copy(deep=True),
        description="the depth camera on each hand (a RealSense D405-like stereo camera beside the gripper body, "
        "looking along the approach); null: none",
    )
    package_paths: list[str] = Field(
        default_factory=list,
        description="folders holding ROS packages (package.xml) for package:// mesh URIs "
        "of `urdf`; the URDF's own folder and its parents are always searched",
    )


class NextagePyBullet(ArmRobot):
    """Kawada NEXTAGE OPEN: two 6-DOF arms (7 with the chest), two-finger grippers, PyBullet world."""

    Settings = NextageSettings
    settings: NextageSettings

    def __init__(self, settings: NextageSettings | dict | None = None, *, seed: int = 0) -> None:
        super().__init__(settings, seed=seed)
        st = self.settings
        if st.base_pose is not None:
            T = np.asarray(st.base_pose, dtype=float)
        else:
            T = geometry.from_rpy(0.0, 0.0, 0.0, (0.0, 0.0, st.table_height + st.waist_above_table))
        arms = {}
        for arm, pre in _PREFIX.items():
            joints = [f"{pre}_JOINT{k}" for k in range(6)]
            home = (READY_POSE if st.home_pose == "ready" else INIT_POSE)[arm]
            if st.use_chest:
                joints = ["CHEST_JOINT0", *joints]
                home = np.concatenate([[0.0], home])
            half = 0.5 * GRIPPER.max_opening
            gripper = GripperJoints(
                [f"{pre}_FINGER0_JOINT", f"{pre}_FINGER1_JOINT"],
                [half, half],
                [0.0, 0.0],
                f"{pre}_TCP_Link",
                [f"{pre}_FINGER0_Link", f"{pre}_FINGER1_Link"],
            )
            arms[arm] = ArmSpec(
                joints,
                f"{pre}_TCP_Link",
                home,
                gripper,
                [f"{pre}_GRIPPER_Link", f"{pre}_FINGER0_Link", f"{pre}_FINGER1_Link"],
            )
        if st.urdf is None:
            urdf = URDF_PATH
        else:
            if not Path(st.urdf).expanduser().is_file():
                raise UserError(
                    f"robot.settings.urdf: {st.urdf} does not exist (relative paths are from the working "
                    f"directory {Path.cwd()})"
                )
            urdf = vendor_urdf(st.urdf, st.package_paths)
        self._setup(urdf, T, arms, nextage_hand(st.grip_force), SRDF_DISABLED)
