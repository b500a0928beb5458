"""Bring-your-own URDF arm: the Franka Panda of pybullet_data, from config only."""

from __future__ import annotations

import numpy as np
import pytest

from asmteach.core.errors import UserError
from asmteach.core.registry import create
from asmteach.plugins.robots.urdf_arm.robot import UrdfArm


@pytest.fixture(scope="module")
def panda() -> UrdfArm:
    with UrdfArm({}) as r:
        yield r


def test_panda_kinematics_agree_with_pybullet(panda: UrdfArm) -> None:
    rng = np.random.default_rng(0)
    lo, hi = panda.joint_limits("main")
    for _ in range(10):
        q = rng.uniform(lo, hi)
        panda.sim.set_joints(panda.joint_names("main"), q)
        assert np.linalg.norm(panda.fk("main", q)[:3, 3] - panda.sim.link_pose("panda_grasptarget")[:3, 3]) < 1e-6
        res = panda.ik("main", panda.fk("main", q))
        assert res.success
        assert np.linalg.norm(panda.fk("main", res.q)[:3, 3] - panda.fk("main", q)[:3, 3]) < 1e-4


def test_panda_home_is_free_and_hand_points_down(panda: UrdfArm) -> None:
    q = panda.home("main")
    assert not panda.in_collision("main", q[None])[0]
    assert panda.fk("main", q)[2, 2] < -0.99
    assert panda.hand.max_width == pytest.approx(0.08)


def test_config_errors_name_the_problem() -> None:
    with pytest.raises(UserError, match="no movable joint named 'panda_joint9'"):
        UrdfArm({"arms": {"main": {"joints": ["panda_joint1", "panda_joint9"], "tcp_link": "panda_hand"}}})
    with pytest.raises(UserError, match="no such URDF"):
        UrdfArm({"urdf": "/nonexistent/robot.urdf"})


def test_registry_builds_both_robots() -> None:
    with create("robots", "urdf_arm", {}) as r:
        assert r.arms == ["main"]
    with create("robots", "nextage_pybullet", {"table_height": 0.1}) as r:
        assert r.arms == ["left", "right"]
        assert r.T_world_base[2, 3] == pytest.approx(0.27)
