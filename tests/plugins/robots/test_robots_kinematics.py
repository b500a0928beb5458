"""IK round trips, finger-order flip, failures with residuals, limits and the Jacobian."""

from __future__ import annotations

import math

import numpy as np
import pytest

from asmteach.core import geometry
from asmteach.core.arm.dls_ik import flip_jaw
from asmteach.core.errors import UserError
from asmteach.plugins.robots.nextage.robot import NextagePyBullet


@pytest.fixture(scope="module")
def robot() -> NextagePyBullet:
    with NextagePyBullet({}, seed=1) as r:
        yield r


@pytest.mark.parametrize("arm", ["left", "right"])
def test_ik_round_trips(robot: NextagePyBullet, arm: str) -> None:
    rng = np.random.default_rng(5)
    lo, hi = robot.joint_limits(arm)
    solved = 0
    for _ in range(40):
        q = rng.uniform(lo, hi)
        T = robot.fk(arm, q)
        res = robot.kin.ik(arm, T, robot.home(arm), rng=rng, flipped=False)
        if res.success:
            solved += 1
            T2 = robot.fk(arm, res.q)
            assert np.linalg.norm(T2[:3, 3] - T[:3, 3]) < 1e-4
            assert geometry.rotation_distance(T2, T) < math.radians(0.1)
            assert np.all(res.q >= lo - 1e-12) and np.all(res.q <= hi + 1e-12)
    assert solved >= 38


def test_ik_with_chest_has_seven_dof() -> None:
    with NextagePyBullet({"use_chest": True}) as r:
        assert r.joint_names("left")[0] == "CHEST_JOINT0" and len(r.home("left")) == 7
        q = r.home("left").copy()
        q[0] = 0.3
        T = r.fk("left", q)
        res = r.ik("left", T)
        assert res.success and np.linalg.norm(r.fk("left", res.q)[:3, 3] - T[:3, 3]) < 1e-4


def test_grasp_ik_tries_the_other_finger_order(robot: NextagePyBullet) -> None:
    # Wrist roll at 0 turned by 180 deg needs +-180 deg on LARM_JOINT5 (limit +-163 deg): only the flip works.
    q = robot.home("left").copy()
    q[5] = 0.0
    T = robot.fk("left", q)
    T_turned = flip_jaw(T)
    res_plain = robot.kin.ik("left", T_turned, robot.home("left"), flipped=False)
    res = robot.kin.ik("left", T_turned, robot.home("left"), flipped=True)
    assert not res_plain.success and "no solution" in res_plain.reason
    assert res.success and res.flipped
    assert np.allclose(robot.fk("left", res.q), T, atol=1e-4)


def test_ik_failure_returns_residual_and_reason(robot: NextagePyBullet) -> None:
    far = np.eye(4)
    far[:3, 3] = [2.0, 0.0, 0.5]
    res = robot.ik("left", far)
    assert not res.success and res.q is None
    assert "outside the workspace" in res.reason and res.residual_pos > 1.0
    # within reach but impossible orientation: TCP pointing up under the table edge near the body
    T = np.eye(4)
    T[:3, 3] = [0.05, 0.4, 0.5]
    res = robot.ik("left", T)
    assert not res.success and "no solution" in res.reason and np.isfinite(res.residual_pos)
    assert not robot.ik("nope", T).success


def test_limits_are_checked(robot: NextagePyBullet) -> None:
    q = robot.home("left").copy()
    q[2] = 0.5  # LARM_JOINT2 upper limit is 0
    with pytest.raises(UserError, match=r"LARM_JOINT2 = 0.500000 rad is outside its limits"):
        robot.fk("left", q)
    with pytest.raises(UserError, match="has 6 joints"):
        robot.fk("left", np.zeros(5))
    with pytest.raises(UserError, match="unknown arm"):
        robot.joint_names("middle")


def test_jacobian_matches_finite_differences(robot: NextagePyBullet) -> None:
    q = robot.home("left")
    J = robot.jacobian("left", q)
    eps = 1e-6
    T0 = robot.fk("left", q)
    for k in range(6):
        dq = np.zeros(6)
        dq[k] = eps
        T1 = robot.fk("left", q + dq)
        assert np.allclose((T1[:3, 3] - T0[:3, 3]) / eps, J[:3, k], atol=1e-5)


@pytest.mark.parametrize("arm", ["left", "right"])
def test_batched_joint_poses_match_pinocchio(robot: NextagePyBullet, arm: str) -> None:
    import pinocchio as pin

    kin = robot.kin
    lo, hi = robot.joint_limits(arm)
    qs = np.random.default_rng(7).uniform(lo, hi, size=(9, len(lo)))
    moving, static = kin.batch_joint_poses(arm, qs)
    assert set(moving) == set(kin.moving_joints(arm)) and len(moving) > len(lo)  # the hand's joints too
    for i, q in enumerate(qs):
        pin.forwardKinematics(kin.model, kin.data, kin.full_q(arm, q))
        for j, T in moving.items():
            assert np.allclose(T[i], kin.T_world_base @ kin.data.oMi[j].homogeneous, atol=1e-12)
    pin.forwardKinematics(kin.model, kin.data, kin.q_full)
    for j in range(kin.model.njoints):
        assert np.allclose(static[j], kin.T_world_base @ kin.data.oMi[j].homogeneous, atol=1e-12)
