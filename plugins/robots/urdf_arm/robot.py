"""Bring-your-own arm: any URDF with a parallel gripper, configured entirely from settings.

Example (the Franka Panda that ships with ``pybullet_data``; the default settings)::

    robot:
      plugin: urdf_arm
      settings:
        urdf: pybullet_data:franka_panda/panda.urdf
        base_pose: {xyz: [0.0, 0.0, 0.0], rpy_deg: [0, 0, 0]}
        arms:
          main:
            joints: [panda_joint1, panda_joint2, ..., panda_joint7]
            tcp_link: panda_grasptarget
            home: [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]
            finger_joints: [panda_finger_joint1, panda_finger_joint2]
            ...

``urdf`` is a file path, or ``pybullet_data:<relative path>`` for robots that
ship with PyBullet. The TCP link's frame must follow :class:`HandSpec`'s
convention (z = approach out of the palm, y = jaw axis); ``hand`` describes
the gripper geometry in that frame. World frame: z up, metres; the table top
is at ``table_height`` (the base pose is independent of it).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pydantic import Field, model_validator

from asmteach.core.arm.robot import ArmRobot, ArmRobotSettings, ArmSpec
from asmteach.core.arm.sim import GripperJoints
from asmteach.core.errors import UserError
from asmteach.core.models import HandSpec, Mat4, StrictModel

__all__ = ["UrdfArm", "UrdfArmSettings", "resolve_urdf"]

PANDA_JOINTS = [f"panda_joint{k}" for k in range(1, 8)]


def resolve_urdf(spec: str) -> Path:
    """A URDF path; ``pybullet_data:<rel>`` is looked up in PyBullet's data folder."""
    if spec.startswith("pybullet_data:"):
        import pybullet_data

        return Path(pybullet_data.getDataPath()) / spec.split(":", 1)[1]
    return Path(spec).expanduser()


class ArmConfig(StrictModel):
    """One arm of the URDF and its gripper (names are URDF joint and link names)."""

    joints: list[str] = Field(min_length=1, description="arm joints from the base to the wrist")
    tcp_link: str = Field(description="link whose frame is the TCP (z approach, y jaw axis)")
    home: list[float] | None = Field(None, description="home configuration, radians; default: zeros clipped")
    finger_joints: list[str] = Field(default_factory=list, description="prismatic finger joints")
    finger_open: list[float] = Field(default_factory=list, description="finger joint values when open")
    finger_closed: list[float] = Field(default_factory=list, description="finger joint values when closed")
    finger_links: list[str] = Field(default_factory=list, description="links that touch a grasped part")
    hand_links: list[str] = Field(default_factory=list, description="links allowed to touch a held part")

    @model_validator(mode="after")
    def _fingers(self) -> ArmConfig:
        n = len(self.finger_joints)
        if len(self.finger_open) != n or len(self.finger_closed) != n:
            raise ValueError(f"finger_open and finger_closed need one value per finger joint ({n})")
        if self.home is not None and len(self.home) != len(self.joints):
            raise ValueError(f"home has {len(self.home)} values for {len(self.joints)} joints")
        return self


def _panda_hand() -> HandSpec:
    # Franka Hand: 0-80 mm stroke; boxes measured from the pybullet_data meshes (TCP frame = panda_grasptarget).
    return HandSpec(name="franka_hand", max_width=0.08, finger_size=[0.012, 0.02, 0.05], pad_size=(0.02, 0.018),
                    palm_center=[0.0, 0.0, -0.075], palm_size=[0.06, 0.2, 0.06], max_force=70.0)


class UrdfArmSettings(ArmRobotSettings):
    """A URDF arm and its gripper, all from config (metres, radians)."""

    urdf: str = Field("pybullet_data:franka_panda/panda.urdf", description="path or pybullet_data:<rel>")
    base_pose: Mat4 = Field(default_factory=lambda: np.eye(4), description="T_world_base of the URDF root")
    arms: dict[str, ArmConfig] = Field(
        default_factory=lambda: {"main": ArmConfig(
            joints=PANDA_JOINTS, tcp_link="panda_grasptarget", home=[0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785],
            finger_joints=["panda_finger_joint1", "panda_finger_joint2"], finger_open=[0.04, 0.04],
            finger_closed=[0.0, 0.0], finger_links=["panda_leftfinger", "panda_rightfinger"],
            hand_links=["panda_hand", "panda_leftfinger", "panda_rightfinger"])},
        min_length=1)
    hand: HandSpec = Field(default_factory=_panda_hand, description="gripper geometry in the TCP frame")
    disabled_pairs: list[tuple[str, str]] = Field(default_factory=list, description="link pairs never checked")
    disable_home_contacts: bool = Field(True, description="also never check link pairs touching at home")
    table_center: tuple[float, float] = (0.5, 0.0)
    table_size: tuple[float, float] = (0.6, 0.8)
    table_height: float = 0.0


class UrdfArm(ArmRobot):
    """Any URDF arm with a parallel gripper, configured from settings (default: Franka Panda)."""

    Settings = UrdfArmSettings
    settings: UrdfArmSettings

    def __init__(self, settings: UrdfArmSettings | dict | None = None, *, seed: int = 0) -> None:
        super().__init__(settings, seed=seed)
        st = self.settings
        urdf = resolve_urdf(st.urdf)
        arms = {}
        for name, a in st.arms.items():
            home = np.asarray(a.home, dtype=float) if a.home is not None else None
            g = GripperJoints(list(a.finger_joints), list(a.finger_open), list(a.finger_closed), a.tcp_link,
                              list(a.finger_links))
            arms[name] = ArmSpec(list(a.joints), a.tcp_link, home, g, list(a.hand_links))
        # The home may be None until the kinematics know the limits: fill it in with zeros clipped to them.
        from asmteach.core.arm.kinematics import Kinematics

        probe = Kinematics(urdf, {n: (s.joints, s.tcp_link) for n, s in arms.items()}, st.base_pose, st.ik)
        for n, s in arms.items():
            if s.home is None:
                s.home = probe.chain(n).home.copy()
            else:
                probe.check_limits(n, s.home)
        known = set(probe.info.links)
        for n, s in arms.items():
            for ln in [*s.gripper.finger_links, *s.hand_links]:
                if ln not in known:
                    raise UserError(f"{urdf.name}: arm {n!r}: no link named {ln!r}")
        self._setup(urdf, st.base_pose, arms, st.hand, list(st.disabled_pairs))
        if st.disable_home_contacts:
            self._disable_home_contacts()

    def _disable_home_contacts(self) -> None:
        """Like MoveIt's setup assistant: link pairs already touching at home are assumed designed to touch."""
        for arm in self.arms:
            for a, b in self.checker.report(arm, self.home(arm)):
                if b != "table" and not a.startswith("held:"):
                    self.checker.disabled.add(frozenset((a, b)))
        self.checker._pairs.clear()
