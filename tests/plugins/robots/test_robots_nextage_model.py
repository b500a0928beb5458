"""The Nextage URDF: generator, pinocchio vs PyBullet FK, upstream reference positions, bad URDFs."""

from __future__ import annotations

import numpy as np
import pytest

from asmteach.core.arm.kinematics import Kinematics
from asmteach.core.arm.sim import PyBulletWorld
from asmteach.core.arm.urdf_check import check_urdf
from asmteach.core.errors import UserError
from asmteach.plugins.robots.nextage.build_urdf import URDF_PATH, build_urdf

ARMS = {
    "left": ([f"LARM_JOINT{k}" for k in range(6)], "LARM_TCP_Link"),
    "right": ([f"RARM_JOINT{k}" for k in range(6)], "RARM_TCP_Link"),
}
# Reference wrist (*ARM_JOINT5_Link origin) positions in the WAIST frame, from the kinematic facts (section 8).
REFERENCE = [
    ([0.6, 0.0, -100.0, -15.2, 9.4, -3.2], (0.3255751238415409, 0.18236314012331808, 0.06762452267747099)),
    ([0.0, 0.0, -130.0, 0.0, 0.0, 0.0], (0.29846, 0.21086, 0.24904)),
    ([15.0, 0.0, -143.0, 0.0, 0.0, 0.0], (0.22374, 0.28839, 0.29379)),
    ([0.0, 0.0, 0.0, 0.0, 0.0, 0.0], (-0.077, 0.08794, -0.2097)),
]


@pytest.fixture(scope="module")
def kin() -> Kinematics:
    return Kinematics(URDF_PATH, ARMS, np.eye(4))


def test_urdf_file_is_generated_from_the_facts() -> None:
    assert URDF_PATH.read_text(encoding="utf-8") == build_urdf()
    info = check_urdf(URDF_PATH)
    assert info.root == "WAIST"
    names = set(info.joints)
    assert {"CHEST_JOINT0", "HEAD_JOINT0", "HEAD_JOINT1"} <= names
    assert {f"{s}ARM_JOINT{k}" for s in "LR" for k in range(6)} <= names
    assert info.joints["LARM_FINGER1_JOINT"]["type"] == "prismatic"


@pytest.mark.parametrize(("deg", "expected"), REFERENCE)
def test_wrist_positions_match_reference(kin: Kinematics, deg: list[float], expected: tuple[float, ...]) -> None:
    q = np.radians(deg)
    qf = kin.full_q("left", q)
    wrist = kin.frame_pose("LARM_JOINT5_Link", qf)[:3, 3]
    assert np.allclose(wrist, expected, atol=2e-5)
    # right arm mirrors: JOINT0, JOINT3, JOINT5 negated
    qr = q * np.array([-1, 1, 1, -1, 1, -1])
    wr = kin.frame_pose("RARM_JOINT5_Link", kin.full_q("right", qr))[:3, 3]
    assert np.allclose(wr, [expected[0], -expected[1], expected[2]], atol=2e-5)


def test_init_pose_tcp_points_down(kin: Kinematics) -> None:
    T = kin.fk("left", np.radians(REFERENCE[0][0]))
    assert T[2, 2] < -0.999  # approach axis (TCP z) straight down
    assert abs(T[1, 1]) > 0.999  # jaw along world y
    wrist = kin.frame_pose("LARM_JOINT5_Link", kin.full_q("left", np.radians(REFERENCE[0][0])))
    assert np.allclose(np.linalg.solve(wrist, T)[:3, 3], [-0.21, 0.0, 0.0], atol=1e-12)


def test_pinocchio_and_pybullet_agree(kin: Kinematics) -> None:
    T_base = np.eye(4)
    T_base[:3, 3] = [0.1, -0.2, 0.3]
    moved = Kinematics(URDF_PATH, ARMS, T_base)
    sim = PyBulletWorld(URDF_PATH, T_base)
    rng = np.random.default_rng(3)
    try:
        m = moved.model
        for _ in range(20):
            q = rng.uniform(m.lowerPositionLimit, m.upperPositionLimit)
            moved.q_full = q
            for j in range(1, m.njoints):
                sim.set_joints([m.names[j]], [q[m.joints[j].idx_q]])
            for link in ("LARM_TCP_Link", "RARM_TCP_Link", "LARM_FINGER1_Link", "HEAD_JOINT1_Link"):
                T_pin = moved.frame_pose(link)
                T_pb = sim.link_pose(link)
                assert np.linalg.norm(T_pin[:3, 3] - T_pb[:3, 3]) < 1e-6
                assert np.allclose(T_pin[:3, :3], T_pb[:3, :3], atol=1e-6)
    finally:
        sim.close()


def test_bad_urdfs_name_file_and_element(tmp_path) -> None:
    bad = tmp_path / "arm.urdf"
    bad.write_text(
        '<robot name="r"><link name="a"/><link name="b"/><joint name="j" type="revolute">'
        '<parent link="a"/><child link="b"/><limit lower="1" upper="0"/></joint></robot>'
    )
    with pytest.raises(UserError, match=r"arm.urdf: <joint name='j'> <limit>: lower 1.0 > upper 0.0"):
        check_urdf(bad)
    bad.write_text(
        '<robot name="r"><link name="a"><visual><geometry><mesh filename="nope.stl"/></geometry>'
        "</visual></link></robot>"
    )
    with pytest.raises(UserError, match=r"<link name='a'> <visual> <mesh filename='nope.stl'>"):
        check_urdf(bad)
    bad.write_text("<robot><link name='a'>")
    with pytest.raises(UserError, match=r"arm.urdf: not well-formed XML at line 1"):
        check_urdf(bad)
    with pytest.raises(UserError, match="no such URDF"):
        check_urdf(tmp_path / "missing.urdf")


def test_unknown_names_are_user_errors() -> None:
    with pytest.raises(UserError, match="no movable joint named 'LARM_JOINT9'"):
        Kinematics(URDF_PATH, {"left": (["LARM_JOINT9"], "LARM_TCP_Link")}, np.eye(4))
    with pytest.raises(UserError, match="no link or frame named 'LARM_TCP'"):
        Kinematics(URDF_PATH, {"left": (ARMS["left"][0], "LARM_TCP")}, np.eye(4))
