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

``urdf`` is a file path, ``pybullet_data:<relative path>`` for robots that
ship with PyBullet, or ``example-robot-data:<relative path>`` (short ``erd:``)
for the robots of the ``example-robot-data`` wheel; ``package://`` mesh URIs
are resolved into a cached copy (:mod:`.compose`), the source is never edited.
An arm without a gripper that opens gets a generated one (``gripper:``, see
:mod:`.gripper`); a tool frame that is not the TCP gets ``tcp_offset:``; an
arm with its own ``urdf`` is placed in the cell at its ``base`` (names in its
settings are its URDF's names; the robot's joint and link names are then
prefixed ``<arm>_``). See ``configs/demo_ur5.yaml``, ``demo_panda.yaml``, ``demo_dual_ur5.yaml``.

The TCP frame must follow :class:`HandSpec`'s convention (z = approach out of
the palm, y = jaw axis); ``hand`` describes the gripper geometry in that frame
(default: the generated gripper's, else the Franka Hand). World frame: z up,
metres; the table top is at ``table_height`` (the base pose is independent of it).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pydantic import Field, model_validator

from asmteach.core.arm.robot import ArmRobot, ArmSpec
from asmteach.core.arm.settings import ArmRobotSettings
from asmteach.core.arm.sim_gripper import GripperJoints
from asmteach.core.errors import UserError
from asmteach.core.models import HandSpec, Mat4, StrictModel
from asmteach.core.urdf import resolve_urdf as resolve_packages
from asmteach.plugins.robots.urdf_arm.compose import ArmSource, compose_urdf, package_paths, readable_source
from asmteach.plugins.robots.urdf_arm.gripper import GripperConfig, gripper_names, hand_of

__all__ = ["UrdfArm", "UrdfArmSettings", "resolve_urdf"]

PANDA_JOINTS = [f"panda_joint{k}" for k in range(1, 8)]


def resolve_urdf(spec: str) -> Path:
    """A URDF file that pinocchio and PyBullet read: a path, ``pybullet_data:<rel>`` or
    ``example-robot-data:<rel>`` (``package://`` URIs resolved into the URDF cache)."""
    src = readable_source(spec)
    if not src.is_file():
        return src  # the readers name the missing file
    return resolve_packages(src, package_paths(spec)).path


class ArmConfig(StrictModel):
    """One arm and its gripper (names are joint and link names of the arm's URDF)."""

    joints: list[str] = Field(min_length=1, description="arm joints from the base to the wrist")
    tcp_link: str | None = Field(
        None,
        description="link whose frame is the TCP (z approach, y jaw axis); "
        "with tcp_offset, the link the TCP is fixed to; not with gripper",
    )
    tcp_offset: Mat4 | None = Field(None, description="T_tcplink_tcp when tcp_link's frame is not the TCP")
    gripper: GripperConfig | None = Field(None, description="generate a parallel gripper (it brings the TCP)")
    urdf: str | None = Field(None, description="this arm's own URDF (path, pybullet_data:, example-robot-data:)")
    base: Mat4 = Field(default_factory=lambda: np.eye(4), description="T_cellbase_root of the arm's own URDF")
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
        if self.gripper is not None and (self.tcp_link or self.tcp_offset is not None or n):
            raise ValueError(
                "a generated gripper brings its TCP and fingers: drop tcp_link, tcp_offset and "
                "finger_* (hand_links may add arm links allowed to touch a held part)"
            )
        if self.gripper is None and not self.tcp_link:
            raise ValueError("give tcp_link (or a gripper to generate)")
        return self

    def spec(self, name: str) -> ArmSpec:
        """The arm with names as in the composed URDF (``<name>_`` prefixed when it has its own URDF)."""
        pre = f"{name}_" if self.urdf else ""
        home = np.asarray(self.home, dtype=float) if self.home is not None else None
        hand_links = [pre + ln for ln in self.hand_links]
        if self.gripper is not None:
            n = gripper_names(name)
            fingers = list(n["fingers"])  # type: ignore[arg-type]
            half = 0.5 * self.gripper.max_opening
            g = GripperJoints(
                list(n["finger_joints"]),
                [half, half],
                [0.0, 0.0],
                str(n["tcp"]),  # type: ignore[arg-type]
                fingers,
            )
            return ArmSpec(
                [pre + j for j in self.joints], str(n["tcp"]), home, g, [*hand_links, str(n["body"]), *fingers]
            )
        tcp = f"{name}_tcp" if self.tcp_offset is not None else pre + str(self.tcp_link)
        g = GripperJoints(
            [pre + j for j in self.finger_joints],
            list(self.finger_open),
            list(self.finger_closed),
            tcp,
            [pre + ln for ln in self.finger_links],
        )
        return ArmSpec([pre + j for j in self.joints], tcp, home, g, hand_links)

    def source(self, name: str) -> ArmSource:
        return ArmSource(name, self.urdf, np.asarray(self.base, float), self.tcp_link, self.tcp_offset, self.gripper)


def _panda_hand() -> HandSpec:
    # Franka Hand: 0-80 mm stroke. The hand's collision mesh (the same in pybullet_data and example-robot-data)
    # spans x +-0.032, y -0.104..0.100, z -0.026..0.066 in panda_hand; the TCP is 0.1034 (example-robot-data)
    # or 0.105 (pybullet_data's panda_grasptarget) out, so the palm reaches to z = -0.037 of the TCP (the
    # nearer of the two). A palm 8 mm shorter let the grasp planner pick grasps whose palm hit the part.
    return HandSpec(
        name="franka_hand",
        max_width=0.08,
        finger_size=[0.012, 0.02, 0.047],
        pad_size=(0.02, 0.018),
        palm_center=[0.0, 0.0, -0.084],
        palm_size=[0.064, 0.205, 0.094],
        max_force=70.0,
    )


class UrdfArmSettings(ArmRobotSettings):
    """A URDF arm (or a cell of arms) and its gripper, all from config (metres, radians)."""

    urdf: str = Field(
        "pybullet_data:franka_panda/panda.urdf",
        description="path, pybullet_data:<rel> or example-robot-data:<rel>; '' when every arm has one",
    )
    base_pose: Mat4 = Field(default_factory=lambda: np.eye(4), description="T_world_base of the URDF (cell) root")
    arms: dict[str, ArmConfig] = Field(
        default_factory=lambda: {
            "main": ArmConfig(
                joints=PANDA_JOINTS,
                tcp_link="panda_grasptarget",
                home=[0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785],
                finger_joints=["panda_finger_joint1", "panda_finger_joint2"],
                finger_open=[0.04, 0.04],
                finger_closed=[0.0, 0.0],
                finger_links=["panda_leftfinger", "panda_rightfinger"],
                hand_links=["panda_hand", "panda_leftfinger", "panda_rightfinger"],
            )
        },
        min_length=1,
        description="each arm by name: its joints, TCP link, home configuration and fingers (default: a Panda)",
    )
    hand: HandSpec | None = Field(
        None, description="gripper geometry in the TCP frame; default: the generated gripper's, else the Franka Hand"
    )
    disabled_pairs: list[tuple[str, str]] = Field(
        default_factory=list, description="link pairs never checked (names in the cell URDF)"
    )
    disable_home_contacts: bool = Field(True, description="also never check link pairs touching at home")
    convex_collision: bool = Field(
        True,
        description="plan with the convex hull of each STL collision mesh, the solid PyBullet collides "
        "(a concave vendor link otherwise passes the planner's check and hits in the simulator)",
    )
    table_center: tuple[float, float] = Field((0.5, 0.0), description="table centre x, y (world), metres")
    table_size: tuple[float, float] = Field((0.6, 0.8), description="table extent along x, y, metres")
    table_height: float = Field(0.0, description="world z of the table top, metres")

    @model_validator(mode="after")
    def _one_hand(self) -> UrdfArmSettings:
        grippers = {a.gripper.model_dump_json() for a in self.arms.values() if a.gripper is not None}
        if len(grippers) > 1 and self.hand is None:
            raise ValueError("the arms' generated grippers differ: the robot has one hand, give the same gripper")
        if not self.urdf and not all(a.urdf for a in self.arms.values()):
            raise ValueError("urdf is empty: every arm then needs its own urdf")
        return self

    def the_hand(self) -> HandSpec:
        """``hand``, else the generated gripper's (with ``grip_force``), else the Franka Hand."""
        if self.hand is not None:
            return self.hand
        for a in self.arms.values():
            if a.gripper is not None:
                return hand_of(a.gripper, self.grip_force)
        return _panda_hand()


class UrdfArm(ArmRobot):
    """Any URDF arm (or cell of arms) with a parallel gripper, configured from settings (default: Franka Panda)."""

    Settings = UrdfArmSettings
    settings: UrdfArmSettings

    def __init__(self, settings: UrdfArmSettings | dict | None = None, *, seed: int = 0) -> None:
        super().__init__(settings, seed=seed)
        st = self.settings
        urdf = compose_urdf(st.urdf, [a.source(n) for n, a in st.arms.items()], convex_collision=st.convex_collision)
        arms = {n: a.spec(n) for n, a in st.arms.items()}
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
        self._setup(urdf, st.base_pose, arms, st.the_hand(), list(st.disabled_pairs))
        self._disable_rigid_pairs()
        if st.disable_home_contacts:
            self._disable_home_contacts()

    def _disable_rigid_pairs(self) -> None:
        """Links moved by the same joint (a gripper fixed to a flange fixed to the wrist) never move relative
        to each other: their contact, if any, is part of the design. Vendor meshes often overlap a fraction of
        a millimetre there, which the simulator's convex hulls see and the planner's exact meshes may not."""
        geoms = [g for g in self.checker.robot if g.joint >= 0]
        for i, a in enumerate(geoms):
            for b in geoms[i + 1 :]:
                if a.joint == b.joint and a.link != b.link:
                    self.checker.disabled.add(frozenset((a.link, b.link)))
        self.checker._pairs.clear()

    def _disable_home_contacts(self) -> None:
        """Like MoveIt's setup assistant: link pairs already touching at home are assumed designed to touch."""
        for arm in self.arms:
            for a, b in self.checker.report(arm, self.home(arm)):
                if b != "table" and not a.startswith("held:"):
                    self.checker.disabled.add(frozenset((a, b)))
        self.checker._pairs.clear()
