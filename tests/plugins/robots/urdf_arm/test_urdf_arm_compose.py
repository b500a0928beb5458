"""The cell URDF of urdf_arm: vendor URDFs resolved, a generated gripper, a TCP offset, arms prefixed."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from asmteach.core.errors import UserError
from asmteach.core.geometry import from_xyz_rpy
from asmteach.plugins.robots.urdf_arm.compose import ArmSource, compose_urdf, readable_source
from asmteach.plugins.robots.urdf_arm.gripper import GripperConfig, hand_of

UR5 = "example-robot-data:ur_description/urdf/ur5_joint_limited_robot.urdf"


def _arm(name: str, **kw) -> ArmSource:
    base = dict(urdf=None, base=np.eye(4), tcp_link=None, tcp_offset=None, gripper=None)
    return ArmSource(name, **(base | kw))


def test_example_robot_data_meshes_resolve_to_files() -> None:
    path = compose_urdf(UR5, [_arm("main", tcp_link="tool0")])
    root = ET.parse(path).getroot()
    meshes = [e.get("filename", "") for e in root.iter("mesh")]
    assert meshes and not any(m.startswith("package://") for m in meshes)
    assert all(Path(m).is_file() for m in meshes)
    assert "package://" not in readable_source(UR5).read_text()


def test_generated_gripper_and_its_hand_follow_handspec() -> None:
    g = GripperConfig(parent="tool0", max_opening=0.06, tcp_depth=0.12)
    root = ET.parse(compose_urdf(UR5, [_arm("main", gripper=g)])).getroot()
    joints = {e.get("name"): e for e in root.findall("joint")}
    axes = [joints[f"main_finger{k}_joint"].find("axis").get("xyz") for k in (0, 1)]
    assert axes == ["0 -1 0", "0 1 0"]  # finger 0 on -y, finger 1 on +y (jaw axis y)
    assert float(joints["main_finger0_joint"].find("limit").get("upper")) == pytest.approx(0.03)
    assert joints["main_gripper_tcp_joint"].find("origin").get("xyz") == "0 0 0.12"
    hand = hand_of(g)
    assert hand.max_width == pytest.approx(0.06)
    # the finger's tip is half a pad beyond the TCP; the palm's front face is where the fingers start
    tip = hand.palm_center[2] + 0.5 * hand.palm_size[2] + hand.finger_size[2]
    assert tip == pytest.approx(0.5 * g.pad_length)


def test_tcp_offset_adds_a_frame_and_arms_with_their_own_urdf_are_prefixed() -> None:
    T = from_xyz_rpy([0.0, 0.0, 0.1], [0.0, 0.0, np.pi / 2])
    arms = [
        _arm("left", urdf=UR5, base=from_xyz_rpy([0, 0.3, 0], [0, 0, 0]), tcp_link="tool0", tcp_offset=T),
        _arm("right", urdf=UR5, base=from_xyz_rpy([0, -0.3, 0], [0, 0, 0]), tcp_link="tool0"),
    ]
    root = ET.parse(compose_urdf("", arms)).getroot()
    links = {e.get("name") for e in root.findall("link")}
    assert {"cell_base", "left_tool0", "right_tool0", "left_tcp", "left_base_link"} <= links
    children = [e.find("child").get("link") for e in root.findall("joint")]
    assert len(children) == len(set(children)) == len(links) - 1  # one tree: every link but the root is a child


def test_bad_cells_are_one_line_errors() -> None:
    with pytest.raises(UserError, match=r"gripper\.parent 'flange' is not a link"):
        compose_urdf(UR5, [_arm("main", gripper=GripperConfig(parent="flange"))])
    with pytest.raises(UserError, match="no such URDF"):
        compose_urdf("example-robot-data:nothing/here.urdf", [_arm("main", tcp_link="x")])
    with pytest.raises(ValueError, match="fingers would have no length"):
        GripperConfig(parent="tool0", tcp_depth=0.05)


def test_convex_collision_points_every_stl_collision_mesh_at_its_hull() -> None:
    import trimesh

    root = ET.parse(compose_urdf(UR5, [_arm("main", tcp_link="tool0")], convex_collision=True)).getroot()
    files = [e.get("filename", "") for c in root.iter("collision") for e in c.iter("mesh")]
    assert files and all("_hull_" in f for f in files)
    assert all(trimesh.load(f, force="mesh").is_convex for f in files)
    visuals = [e.get("filename", "") for v in root.iter("visual") for e in v.iter("mesh")]
    assert not any("_hull_" in f for f in visuals)
