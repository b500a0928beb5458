"""Writes ``nextage.urdf`` from the kinematic facts of the Kawada NEXTAGE OPEN.

The numbers come from the upstream ``NextageOpen.urdf`` (tree, limits, masses,
inertias) and the OpenHRP ``main.wrl`` (hardware speed limits, exact limit
values, link extents), summarised in the project's reference notes. The
collision and visual geometry is primitive (boxes and cylinders) so that
collision checking is fast and exact. The stock chuck hand is replaced by a
two-finger parallel gripper (Robotiq 2F-85-like, 0-85 mm opening) mounted at
the hand interface ``(-0.065, 0, 0)`` of each ``*ARM_JOINT5_Link``.

Units: metres, radians, kilograms. Run ``python -m
asmteach.plugins.robots.nextage.build_urdf`` to regenerate the file; a test
checks the file matches this generator.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

__all__ = ["GRIPPER", "MATERIALS", "URDF_PATH", "build_urdf", "gripper_xml"]

URDF_PATH = Path(__file__).with_name("nextage.urdf")

Vec = tuple[float, float, float]
ZERO: Vec = (0.0, 0.0, 0.0)
HALF_PI = 1.5707963267948966
SHOULDER_ROLL = 0.261799  # the shoulders are tilted by 15 deg about x (upstream rpy)

# Exact limit values of main.wrl (radians).
LIM_163 = 2.8448866807507569
LIM_70 = 1.2217304763960306
LIM_M20 = -0.3490658503988659
LIM_88 = 1.5358897417550099
LIM_P60 = 1.0471975511965976
LIM_M140 = -2.4434609527920612
LIM_M158 = -2.7576202181510405
LIM_P165 = 2.8797932657906435
LIM_M105 = -1.8325957145940461
LIM_100 = 1.7453292519943295


@dataclass(frozen=True)
class GripperGeometry:
    """The parallel gripper of this project, in its mount frame (= ``*ARM_JOINT5_Link`` axes).

    The approach direction is -x; the fingers slide along +-y. EST values
    (product outline of a Robotiq 2F-85), see the reference notes, section 9.
    """

    mount_x: float = -0.065  # hand interface in *ARM_JOINT5_Link
    tcp_depth: float = 0.145  # mount -> pad centre along the approach axis
    body_size: Vec = (0.075, 0.090, 0.065)  # approach, opening, third axis
    finger_thickness: float = 0.010  # along the opening direction (y)
    finger_width: float = 0.022  # along the third axis (z of the mount frame)
    pad_length: float = 0.035  # along the approach axis, centred on the TCP
    max_opening: float = 0.085
    body_mass: float = 0.8
    finger_mass: float = 0.05
    finger_speed: float = 0.15  # m/s per finger
    finger_effort: float = 100.0  # N per finger (the URDF limit; the grip force is set in the simulator)

    @property
    def finger_length(self) -> float:
        """Finger box from the body face to the fingertip (metres)."""
        return self.tcp_depth + 0.5 * self.pad_length - self.body_size[0]

    @property
    def finger_center_x(self) -> float:
        """Finger box centre along x of the mount frame (negative: toward the object)."""
        return -(self.body_size[0] + 0.5 * self.finger_length)


GRIPPER = GripperGeometry()


@dataclass(frozen=True)
class Inertial:
    mass: float
    com: Vec
    ixx: float
    ixy: float
    ixz: float
    iyy: float
    iyz: float
    izz: float


@dataclass(frozen=True)
class Shape:
    kind: str  # "box" or "cylinder"
    size: tuple[float, ...]  # box: (x, y, z); cylinder: (radius, length)
    xyz: Vec = ZERO
    rpy: Vec = ZERO
    name: str = ""


def _f(v: float) -> str:
    s = f"{v:.10g}"
    return "0" if s in ("-0", "0") else s


def _v(v: tuple[float, ...]) -> str:
    return " ".join(_f(x) for x in v)


def _geometry(s: Shape) -> str:
    if s.kind == "box":
        return f'<box size="{_v(s.size)}"/>'
    return f'<cylinder radius="{_f(s.size[0])}" length="{_f(s.size[1])}"/>'


def _link(name: str, inertial: Inertial, shapes: list[Shape], color: str) -> str:
    i = inertial
    out = [f'  <link name="{name}">']
    out.append(
        f'    <inertial>\n      <origin xyz="{_v(i.com)}" rpy="0 0 0"/>\n      <mass value="{_f(i.mass)}"/>\n'
        f'      <inertia ixx="{_f(i.ixx)}" ixy="{_f(i.ixy)}" ixz="{_f(i.ixz)}" iyy="{_f(i.iyy)}" '
        f'iyz="{_f(i.iyz)}" izz="{_f(i.izz)}"/>\n    </inertial>'
    )
    for s in shapes:
        origin = f'<origin xyz="{_v(s.xyz)}" rpy="{_v(s.rpy)}"/>'
        out.append(
            f'    <visual name="{s.name}">\n      {origin}\n      <geometry>{_geometry(s)}</geometry>\n'
            f'      <material name="{color}"/>\n    </visual>'
        )
        out.append(
            f'    <collision name="{s.name}">\n      {origin}\n      <geometry>{_geometry(s)}</geometry>\n'
            "    </collision>"
        )
    out.append("  </link>")
    return "\n".join(out)


def _joint(
    name: str,
    kind: str,
    parent: str,
    child: str,
    xyz: Vec,
    rpy: Vec = ZERO,
    axis: Vec | None = None,
    limits: tuple[float, float, float, float] | None = None,
    damping: float = 0.2,
) -> str:
    out = [f'  <joint name="{name}" type="{kind}">']
    out.append(f'    <parent link="{parent}"/>\n    <child link="{child}"/>')
    out.append(f'    <origin xyz="{_v(xyz)}" rpy="{_v(rpy)}"/>')
    if axis is not None:
        out.append(f'    <axis xyz="{_v(axis)}"/>')
    if limits is not None:
        lo, hi, effort, vel = limits
        out.append(f'    <limit lower="{_f(lo)}" upper="{_f(hi)}" effort="{_f(effort)}" velocity="{_f(vel)}"/>')
        out.append(f'    <dynamics damping="{_f(damping)}" friction="0"/>')
    out.append("  </joint>")
    return "\n".join(out)


def _box_inertial(mass: float, size: Vec, com: Vec) -> Inertial:
    x, y, z = size
    k = mass / 12.0
    return Inertial(mass, com, k * (y * y + z * z), 0.0, 0.0, k * (x * x + z * z), 0.0, k * (x * x + y * y))


def _mirror(shape: Shape) -> Shape:
    """The right-arm primitive of a left-arm one (y negated, roll negated)."""
    return Shape(
        shape.kind,
        shape.size,
        (shape.xyz[0], -shape.xyz[1], shape.xyz[2]),
        (-shape.rpy[0], shape.rpy[1], -shape.rpy[2]),
        shape.name,
    )


def _mirror_inertial(i: Inertial) -> Inertial:
    """Right-arm rule checked upstream: CoM y, ixy and iyz negated."""
    return Inertial(i.mass, (i.com[0], -i.com[1], i.com[2]), i.ixx, -i.ixy, i.ixz, i.iyy, -i.iyz, i.izz)


# Left-arm link data: (AABB size, AABB centre) of section 3.1 and the URDF inertials of section 4.
_LARM_BOXES: list[tuple[Vec, Vec]] = [
    ((0.0867, 0.0938, 0.156), (-0.00135, 0.0074, 0.0166)),
    ((0.1173, 0.1495, 0.321), (-0.02235, 0.11475, -0.1245)),
    ((0.1038, 0.1248, 0.1877), (-0.017, 0.0214, -0.05915)),
    ((0.0719, 0.0995, 0.1182), (-0.00005, 0.01325, -0.1991)),
    ((0.0745, 0.0978, 0.1406), (-0.00375, 0.0224, -0.0459)),
]
_LARM_INERTIALS: list[Inertial] = [
    Inertial(
        1.32626,
        (-0.00226388, -0.00521383, 0.0156081),
        0.00207537,
        0.00011276,
        8.927e-05,
        0.00240295,
        -4.57e-05,
        0.00141912,
    ),
    Inertial(
        1.14898,
        (-5.236e-05, 0.0583134, -0.107061),
        0.0154168,
        9.95417e-07,
        3.38147e-06,
        0.0147117,
        0.00213719,
        0.0012658,
    ),
    Inertial(
        0.577518, (-2.254e-05, 0.00167107, -0.0715116), 0.00143966, -3e-07, 1.2e-06, 0.00141763, -7.596e-05, 0.0001972
    ),
    Inertial(
        0.457418, (-1.788e-05, -0.00395812, -0.20273), 0.00069205, 3e-08, 5.2e-07, 0.00068903, -1.915e-05, 0.00013509
    ),
    Inertial(
        0.418434,
        (0.00243131, 0.00379733, -0.0577036),
        0.00052016,
        1.69e-06,
        7.9e-06,
        0.00050569,
        -5.377e-05,
        0.00014004,
    ),
    Inertial(
        1.05156, (-0.048476, -3.2e-06, -0.0388988), 0.00194072, 1.1e-07, -0.00042482, 0.00209392, 1.2e-07, 0.00035788
    ),
]
# Wrist-roll housing and tool changer stay on *ARM_JOINT5_Link; the stock chuck hand is replaced.
_WRIST_SHAPES = [
    Shape("cylinder", (0.022, 0.038), (0.019, 0.0, 0.0), (0.0, HALF_PI, 0.0), "wrist_roll_housing"),
    Shape("box", (0.065, 0.067, 0.124), (-0.0325, 0.0035, -0.032), ZERO, "tool_changer"),
]

# Joint table of section 2 for the left arm: (xyz, rpy, axis, lower, upper, effort, hw velocity).
_LARM_JOINTS: list[tuple[Vec, Vec, Vec, float, float, float, float]] = [
    ((0.0, 0.145, 0.370296), (-SHOULDER_ROLL, 0.0, 0.0), (0, 0, 1), -LIM_88, LIM_88, 150, 3.00197),
    (ZERO, ZERO, (0, 1, 0), LIM_M140, LIM_P60, 200, 2.32129),
    ((0.0, 0.095, -0.25), ZERO, (0, 1, 0), LIM_M158, 0.0, 100, 3.9968),
    ((-0.03, 0.0, 0.0), ZERO, (0, 0, 1), LIM_M105, LIM_P165, 100, 4.60767),
    ((0.0, 0.0, -0.235), ZERO, (0, 1, 0), -LIM_100, LIM_100, 100, 3.90954),
    ((-0.047, 0.0, -0.09), ZERO, (1, 0, 0), -LIM_163, LIM_163, 100, 5.23599),
]
_RARM_VEL = [3.00197, 2.32129, 3.75246, 4.60767, 3.90954, 5.23599]


def gripper_xml(prefix: str, parent: str) -> list[str]:
    """Links and joints of one two-finger gripper mounted on ``parent`` (a ``*ARM_JOINT5_Link``).

    The mount is the hand interface ``(GRIPPER.mount_x, 0, 0)`` of ``parent``; links are
    ``{prefix}_GRIPPER_Link``, ``{prefix}_FINGER0/1_Link`` and ``{prefix}_TCP_Link``. Also used to put
    this gripper on the vendor's URDF (:mod:`asmteach.plugins.robots.nextage.vendor`).
    """
    parts: list[str] = []
    g = GRIPPER
    grip = f"{prefix}_GRIPPER_Link"
    parts.append(_joint(f"{prefix}_GRIPPER_MOUNT", "fixed", parent, grip, (g.mount_x, 0.0, 0.0)))
    body_c = (-0.5 * g.body_size[0], 0.0, 0.0)
    parts.append(
        _link(
            grip,
            _box_inertial(g.body_mass, g.body_size, body_c),
            [Shape("box", g.body_size, body_c, ZERO, "gripper_body")],
            "gripper",
        )
    )
    fsize = (g.finger_length, g.finger_thickness, g.finger_width)
    for f, sign in ((0, -1.0), (1, 1.0)):
        link = f"{prefix}_FINGER{f}_Link"
        # Joint value = half the opening; at 0 the inner faces meet on the jaw plane y = 0.
        parts.append(
            _joint(
                f"{prefix}_FINGER{f}_JOINT",
                "prismatic",
                grip,
                link,
                ZERO,
                ZERO,
                (0, sign, 0),
                (0.0, 0.5 * g.max_opening, g.finger_effort, g.finger_speed),
                damping=1.0,
            )
        )
        c = (g.finger_center_x, sign * 0.5 * g.finger_thickness, 0.0)
        parts.append(
            _link(link, _box_inertial(g.finger_mass, fsize, c), [Shape("box", fsize, c, ZERO, "finger")], "finger")
        )
    tcp = f"{prefix}_TCP_Link"
    # TCP frame: z = approach (-x of the mount), y = jaw axis (+y of the mount), x = y cross z.
    parts.append(_joint(f"{prefix}_TCP_JOINT", "fixed", grip, tcp, (-g.tcp_depth, 0.0, 0.0), (0.0, -HALF_PI, 0.0)))
    parts.append(
        f'  <link name="{tcp}">\n    <inertial>\n      <origin xyz="0 0 0" rpy="0 0 0"/>\n'
        '      <mass value="0.001"/>\n      <inertia ixx="1e-07" ixy="0" ixz="0" iyy="1e-07" iyz="0" '
        'izz="1e-07"/>\n    </inertial>\n  </link>'
    )
    return parts


def _arm(prefix: str, side: float) -> list[str]:
    """Links and joints of one arm and its gripper; ``side`` is +1 (left) or -1 (right)."""
    parts: list[str] = []
    parent = "CHEST_JOINT0_Link"
    for k, (xyz, rpy, axis, lo, hi, effort, vel) in enumerate(_LARM_JOINTS):
        link = f"{prefix}_JOINT{k}_Link"
        if side < 0:
            xyz = (xyz[0], -xyz[1], xyz[2])
            rpy = (-rpy[0], rpy[1], -rpy[2])
            vel = _RARM_VEL[k]
            if k == 3:  # RARM_JOINT3 limits are the mirror of LARM_JOINT3's
                lo, hi = -hi, -lo
        parts.append(_joint(f"{prefix}_JOINT{k}", "revolute", parent, link, xyz, rpy, axis, (lo, hi, effort, vel)))
        inertial = _LARM_INERTIALS[k] if side > 0 else _mirror_inertial(_LARM_INERTIALS[k])
        if k < 5:
            size, centre = _LARM_BOXES[k]
            shape = Shape("box", size, centre, ZERO, f"{prefix.lower()}_link{k}")
            shapes = [shape if side > 0 else _mirror(shape)]
        else:
            shapes = list(_WRIST_SHAPES)  # identical on both arms
        parts.append(_link(link, inertial, shapes, "arm"))
        parent = link
    parts += gripper_xml(prefix, parent)
    return parts


MATERIALS = [
    '  <material name="body"><color rgba="0.85 0.85 0.85 1"/></material>',
    '  <material name="arm"><color rgba="0.95 0.95 0.95 1"/></material>',
    '  <material name="gripper"><color rgba="0.2 0.2 0.2 1"/></material>',
    '  <material name="finger"><color rgba="0.35 0.35 0.4 1"/></material>',
]
"""URDF material lines of this model (the gripper's links name ``gripper`` and ``finger``)."""


def build_urdf() -> str:
    """The NEXTAGE OPEN URDF text with primitive geometry and the two-finger grippers."""
    waist = [
        Shape("box", (0.5874, 0.5878, 0.51), (-0.1829, 0.0, -0.715), ZERO, "lower_cabinet"),
        Shape("box", (0.5677, 0.27, 0.301), (-0.18385, 0.0, -0.3095), ZERO, "upper_stand"),
        Shape("cylinder", (0.063, 0.3886), (0.0, 0.0, 0.0353), ZERO, "column"),
    ]
    chest = [
        # Upper torso down to z 0.3449 (the reference split starts it at 0.3543): the split left a 9.4 mm slab
        # between the two torso boxes where the vendor's CHEST mesh has its shell (1.8 % of its surface, 4.7 mm
        # outside our shapes; benchmarks/nextage_vendor.py). x, y extents unchanged.
        Shape("box", (0.2717, 0.2246, 0.209), (-0.05095, 0.0, 0.4494), ZERO, "upper_torso"),
        Shape("box", (0.2127, 0.224, 0.1153), (-0.03365, 0.0, 0.28725), ZERO, "lower_torso"),
        Shape(
            "box",
            (0.1763, 0.1168, 0.0634),
            (-0.0206, 0.16292, 0.49822),
            (-SHOULDER_ROLL, 0.0, 0.0),
            "shoulder_cap_left",
        ),
        Shape(
            "box",
            (0.1763, 0.1168, 0.0634),
            (-0.0206, -0.16292, 0.49822),
            (SHOULDER_ROLL, 0.0, 0.0),
            "shoulder_cap_right",
        ),
        Shape("cylinder", (0.037, 0.078), (0.0, 0.12455, 0.29399), (-SHOULDER_ROLL, 0.0, 0.0), "shoulder_housing_left"),
        Shape(
            "cylinder", (0.037, 0.078), (0.0, -0.12455, 0.29399), (SHOULDER_ROLL, 0.0, 0.0), "shoulder_housing_right"
        ),
    ]
    head0 = [Shape("box", (0.083, 0.072, 0.0505), (-0.0125, 0.007, -0.00225), ZERO, "neck_yaw_housing")]
    head1 = [
        Shape("box", (0.04, 0.058, 0.09), (0.0, 0.0005, 0.025), ZERO, "neck_post"),
        Shape("box", (0.2385, 0.2182, 0.1179), (-0.03535, 0.0, 0.12895), ZERO, "head"),
    ]
    parts = [
        '<?xml version="1.0"?>',
        "<!-- Kawada NEXTAGE OPEN with primitive geometry and two-finger grippers (0-85 mm).",
        "     Generated by asmteach/plugins/robots/nextage/build_urdf.py; do not edit by hand.",
        "     Units: metres, radians, kilograms. Root: WAIST (x forward, y left, z up). -->",
        '<robot name="NextageOpen">',
        *MATERIALS,
        _link("WAIST", Inertial(1000.0, ZERO, 20.0, 0.0, 0.0, 20.0, 0.0, 20.0), waist, "body"),
        _joint(
            "CHEST_JOINT0",
            "revolute",
            "WAIST",
            "CHEST_JOINT0_Link",
            ZERO,
            ZERO,
            (0, 0, 1),
            (-LIM_163, LIM_163, 100, 1.91986),
        ),
        _link(
            "CHEST_JOINT0_Link",
            Inertial(3.0, ZERO, 0.0639575, -0.00022833, 0.00011172, 0.0310845, 6.48e-05, 0.0501107),
            chest,
            "body",
        ),
        _joint(
            "HEAD_JOINT0",
            "revolute",
            "CHEST_JOINT0_Link",
            "HEAD_JOINT0_Link",
            (0.0, 0.0, 0.5695),
            ZERO,
            (0, 0, 1),
            (-LIM_70, LIM_70, 100, 2.61799),
        ),
        _link(
            "HEAD_JOINT0_Link",
            Inertial(
                0.317929,
                (-2.292e-05, 0.00547848, -0.00784016),
                0.00027682,
                3e-08,
                -3.3e-07,
                0.00013009,
                -1.092e-05,
                0.00020954,
            ),
            head0,
            "body",
        ),
        _joint(
            "HEAD_JOINT1",
            "revolute",
            "HEAD_JOINT0_Link",
            "HEAD_JOINT1_Link",
            ZERO,
            ZERO,
            (0, 1, 0),
            (LIM_M20, LIM_70, 100, 4.36332),
        ),
        _link("HEAD_JOINT1_Link", Inertial(0.0808593, ZERO, 0.001, 0.0, 0.0, 0.001, 0.0, 0.001), head1, "body"),
        *_arm("LARM", 1.0),
        *_arm("RARM", -1.0),
        "</robot>",
        "",
    ]
    return "\n".join(parts)


if __name__ == "__main__":
    URDF_PATH.write_text(build_urdf(), encoding="utf-8")
    print(f"wrote {URDF_PATH}")
