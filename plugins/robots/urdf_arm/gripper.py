"""A two-finger parallel gripper generated from config, for arms that come without one.

The UR5 of ``example-robot-data`` ends at its tool flange (``tool0``; its
``ur5_gripper.urdf`` only adds fixed boxes that do not open), so a config can
mount this gripper on any link. Defaults: a Robotiq 2F-85-like gripper
(0-85 mm opening), the same outline as the Nextage's.

Mount frame (``mount`` in the parent link): z = approach, out of the flange
toward the object; y = jaw axis (finger 0 on -y, finger 1 on +y); x = y cross z.
The body is a box from z = 0 to ``body_size[2]``; each finger hangs from the
body's face to ``pad_length / 2`` beyond the TCP, which sits ``tcp_depth`` along
z. Finger joints are prismatic along -+y; the value is half the opening (0 =
closed). Metres, kilograms, newtons.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
from pydantic import Field, model_validator

from asmteach.core import geometry
from asmteach.core.models import HandSpec, Mat4, StrictModel

__all__ = ["GripperConfig", "frame_link", "gripper_elements", "gripper_names", "hand_of", "origin_xml"]


class GripperConfig(StrictModel):
    """A generated parallel gripper (metres, kilograms, newtons, m/s); see the module doc for its frame."""

    parent: str = Field(description="link it is mounted on (a name of the arm's URDF, e.g. tool0)")
    mount: Mat4 = Field(default_factory=lambda: np.eye(4), description="T_parent_mount")
    max_opening: float = Field(0.085, gt=0.0, le=0.3, description="full stroke")
    tcp_depth: float = Field(0.145, gt=0.0, description="mount -> pad centre along the approach axis")
    body_size: tuple[float, float, float] = Field((0.065, 0.09, 0.075), description="x, y (jaw axis), z (approach)")
    finger_thickness: float = Field(0.010, gt=0.0, description="along the jaw axis")
    finger_width: float = Field(0.022, gt=0.0, description="along x")
    pad_length: float = Field(0.035, gt=0.0, description="contact pad along the approach axis, centred on the TCP")
    body_mass: float = Field(0.8, gt=0.0)
    finger_mass: float = Field(0.05, gt=0.0)
    finger_speed: float = Field(0.15, gt=0.0, description="per finger")
    finger_effort: float = Field(100.0, gt=0.0, description="per finger (URDF limit; the grip force is a setting)")

    @model_validator(mode="after")
    def _fingers_reach(self) -> GripperConfig:
        if self.finger_length <= 0.0:
            raise ValueError(
                f"tcp_depth {self.tcp_depth} + pad_length / 2 must exceed the body depth "
                f"{self.body_size[2]} (the fingers would have no length)"
            )
        return self

    @property
    def finger_length(self) -> float:
        """Finger box from the body face to the fingertip (metres)."""
        return self.tcp_depth + 0.5 * self.pad_length - self.body_size[2]


def gripper_names(arm: str) -> dict[str, object]:
    """Link and joint names of arm ``arm``'s generated gripper."""
    return {
        "body": f"{arm}_gripper",
        "fingers": [f"{arm}_finger0", f"{arm}_finger1"],
        "finger_joints": [f"{arm}_finger0_joint", f"{arm}_finger1_joint"],
        "tcp": f"{arm}_gripper_tcp",
    }


def hand_of(g: GripperConfig, max_force: float = 40.0) -> HandSpec:
    """The :class:`HandSpec` of the generated gripper, in its TCP frame (metres, newtons)."""
    return HandSpec(
        name="generated_2finger",
        max_width=g.max_opening,
        min_width=0.0,
        finger_size=[g.finger_thickness, g.finger_width, g.finger_length],
        pad_size=(g.finger_width, g.pad_length),
        palm_center=[0.0, 0.0, -g.tcp_depth + 0.5 * g.body_size[2]],
        palm_size=list(g.body_size),
        max_force=max_force,
    )


def _f(v: float) -> str:
    s = f"{v:.10g}"
    return "0" if s in ("-0", "0") else s


def _v(v) -> str:
    return " ".join(_f(float(x)) for x in v)


def origin_xml(T: np.ndarray) -> str:
    """``<origin>`` of the transform ``T`` (metres; fixed-axis roll, pitch, yaw in radians)."""
    T = np.asarray(T, float)
    return f'<origin xyz="{_v(T[:3, 3])}" rpy="{_v(geometry.rpy(T))}"/>'


def _box_link(name: str, mass: float, size, centre, material: str) -> ET.Element:
    sx, sy, sz = size
    ixx, iyy, izz = (mass / 12.0 * (b * b + c * c) for b, c in ((sy, sz), (sx, sz), (sx, sy)))
    c = _v(centre)
    return ET.fromstring(
        f'<link name="{name}"><inertial><origin xyz="{c}" rpy="0 0 0"/><mass value="{_f(mass)}"/>'
        f'<inertia ixx="{_f(ixx)}" ixy="0" ixz="0" iyy="{_f(iyy)}" iyz="0" izz="{_f(izz)}"/></inertial>'
        f'<visual><origin xyz="{c}" rpy="0 0 0"/><geometry><box size="{_v(size)}"/></geometry>'
        f'<material name="{material}"/></visual>'
        f'<collision><origin xyz="{c}" rpy="0 0 0"/><geometry><box size="{_v(size)}"/></geometry></collision></link>'
    )


def gripper_elements(arm: str, parent: str, g: GripperConfig) -> list[ET.Element]:
    """URDF links, joints and materials of the gripper of ``arm``, mounted on link ``parent`` at ``g.mount``."""
    n = gripper_names(arm)
    body, tcp = str(n["body"]), str(n["tcp"])
    dark, grey = f"{arm}_gripper_dark", f"{arm}_gripper_grey"
    out = [
        ET.fromstring(f'<material name="{dark}"><color rgba="0.2 0.2 0.2 1"/></material>'),
        ET.fromstring(f'<material name="{grey}"><color rgba="0.35 0.35 0.4 1"/></material>'),
        ET.fromstring(
            f'<joint name="{body}_mount" type="fixed">{origin_xml(g.mount)}<parent link="{parent}"/>'
            f'<child link="{body}"/></joint>'
        ),
        _box_link(body, g.body_mass, g.body_size, (0.0, 0.0, 0.5 * g.body_size[2]), dark),
    ]
    size = (g.finger_width, g.finger_thickness, g.finger_length)
    half = 0.5 * g.max_opening
    for k, sign in ((0, -1.0), (1, 1.0)):
        link, joint = n["fingers"][k], n["finger_joints"][k]  # type: ignore[index]
        # joint value = half the opening: at 0 the inner faces meet on the jaw plane y = 0
        out.append(
            ET.fromstring(
                f'<joint name="{joint}" type="prismatic"><origin xyz="0 0 0" rpy="0 0 0"/><parent link="{body}"/>'
                f'<child link="{link}"/><axis xyz="0 {_f(sign)} 0"/>'
                f'<limit lower="0" upper="{_f(half)}" effort="{_f(g.finger_effort)}" velocity="{_f(g.finger_speed)}"/>'
                '<dynamics damping="1.0"/></joint>'
            )
        )
        centre = (0.0, sign * 0.5 * g.finger_thickness, g.body_size[2] + 0.5 * g.finger_length)
        out.append(_box_link(str(link), g.finger_mass, size, centre, grey))
    out.append(
        ET.fromstring(
            f'<joint name="{tcp}_joint" type="fixed"><origin xyz="0 0 {_f(g.tcp_depth)}" rpy="0 0 0"/>'
            f'<parent link="{body}"/><child link="{tcp}"/></joint>'
        )
    )
    out.append(frame_link(tcp))
    return out


def frame_link(name: str) -> ET.Element:
    """A link that is only a frame (a TCP): a tiny mass with its inertial frame on the link frame, since
    PyBullet welds a held part to the TCP link's inertial frame."""
    return ET.fromstring(
        f'<link name="{name}"><inertial><origin xyz="0 0 0" rpy="0 0 0"/><mass value="0.001"/>'
        '<inertia ixx="1e-07" ixy="0" ixz="0" iyy="1e-07" iyz="0" izz="1e-07"/></inertial></link>'
    )
