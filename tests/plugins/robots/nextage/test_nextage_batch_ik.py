"""Batched IK of the Nextage: same answers as the one-target solver, faster; log6 against pinocchio."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation

from asmteach.core.arm.batch_ik import _ChainSolver, _log6_error, _rotvec, ik_many
from asmteach.core.interfaces import IKResult, Robot
from asmteach.plugins.robots.nextage.robot import NextagePyBullet

FLIP = np.diag([-1.0, -1.0, 1.0, 1.0])


@pytest.fixture(scope="module")
def robot() -> NextagePyBullet:
    with NextagePyBullet({"ik": {"max_starts": 4}}) as r:
        yield r


def _reachable(robot: NextagePyBullet, arm: str, n: int, seed: int) -> np.ndarray:
    lo, hi = robot.joint_limits(arm)
    qs = np.random.default_rng(seed).uniform(lo, hi, size=(n, len(lo)))
    return np.stack([robot.fk(arm, q) for q in qs])


def test_log6_error_matches_pinocchio() -> None:
    rng = np.random.default_rng(0)
    T = np.stack([pin.SE3.Random().homogeneous for _ in range(20)])
    D = np.stack([pin.SE3.Random().homogeneous for _ in range(20)])
    e, p, w = _log6_error(T, D)
    for k in range(20):
        ref = pin.log6(pin.SE3(T[k]).actInv(pin.SE3(D[k]))).vector
        assert np.allclose(e[k], ref, atol=1e-9)
        assert np.allclose(p[k], (np.linalg.inv(T[k]) @ D[k])[:3, 3], atol=1e-12)
    # tiny rotations use the series limit of V^-1
    small = T.copy()
    small[:, :3, 3] += rng.normal(0, 0.01, size=(20, 3))
    e, _, w = _log6_error(T, small)
    assert np.allclose(w, 0.0, atol=1e-7)
    assert np.allclose(e[:, :3], np.einsum("nji,nj->ni", T[:, :3, :3], small[:, :3, 3] - T[:, :3, 3]), atol=1e-9)


@pytest.mark.parametrize("arm", ["left", "right"])
def test_solutions_reach_their_targets_as_often_as_one_by_one(robot: NextagePyBullet, arm: str) -> None:
    T = _reachable(robot, arm, 120, seed=3)
    seed = robot.home(arm)
    batch = robot.ik_many(arm, T, seed)
    single = [robot.kin.ik(arm, t, seed, rng=np.random.default_rng(0)) for t in T]
    assert len(batch) == len(T)
    for t, r in zip(T, batch, strict=True):
        if r.success:
            got = robot.fk(arm, r.q) @ (FLIP if r.flipped else np.eye(4))
            assert np.linalg.norm(got[:3, 3] - t[:3, 3]) < 2e-5
            assert np.allclose(got[:3, :3], t[:3, :3], atol=2e-4)
            lo, hi = robot.joint_limits(arm)
            assert np.all(r.q >= lo - 1e-9) and np.all(r.q <= hi + 1e-9)
    n_batch, n_single = sum(r.success for r in batch), sum(r.success for r in single)
    assert n_batch >= n_single - 3 and n_batch >= 0.85 * len(T)


def test_failures_say_why(robot: NextagePyBullet) -> None:
    T = np.stack([np.eye(4)] * 3)
    T[0, :3, 3] = (2.0, 0.0, 0.5)  # metres beyond any reach
    T[1, :3, 3] = _ChainSolver(robot.kin, robot.kin.chain("left")).shoulder  # the hand cannot fold onto it
    T[2, 0, 0] = np.nan
    res = robot.ik_many("left", T)
    assert [r.success for r in res] == [False, False, False]
    assert "outside the workspace" in res[0].reason
    assert res[2].reason == "the target is not a finite 4x4 pose"
    assert res[1].reason.startswith("no solution within the joint limits") and np.isfinite(res[1].residual_pos)
    assert "unknown arm" in robot.ik_many("middle", T[:1])[0].reason


def test_seeds_per_target_pick_the_nearby_solution(robot: NextagePyBullet) -> None:
    arm = "right"
    lo, hi = robot.joint_limits(arm)
    qs = np.random.default_rng(5).uniform(lo, hi, size=(30, 6))
    T = np.stack([robot.fk(arm, q) for q in qs])
    res = ik_many(robot.kin, arm, T, qs + 0.01, flipped=False)
    assert all(r.success and not r.flipped for r in res)
    assert max(float(np.max(np.abs(r.q - q))) for r, q in zip(res, qs, strict=True)) < 0.05


def test_jaw_flip_solves_more_targets(robot: NextagePyBullet) -> None:
    arm = "left"
    T = _reachable(robot, arm, 40, seed=8)
    flipped_targets = T @ FLIP
    res = ik_many(robot.kin, arm, flipped_targets, robot.home(arm), flipped=True)
    plain = ik_many(robot.kin, arm, flipped_targets, robot.home(arm), flipped=False)
    for r, p in zip(res, plain, strict=True):
        if p.success:
            assert r.success
    assert sum(r.success for r in res) > sum(p.success for p in plain)
    for t, r in zip(flipped_targets, res, strict=True):
        if r.success:
            assert np.allclose(robot.fk(arm, r.q) @ (FLIP if r.flipped else np.eye(4)), t, atol=2e-4)


def test_default_ik_many_solves_one_after_the_other() -> None:
    class OneAtATime(Robot):
        arms = ("a",)
        hand = None
        joint_names = joint_limits = home = fk = set_obstacles = attach = in_collision = clearance = None

        def ik(self, arm: str, T_world_tcp: np.ndarray, q_seed: np.ndarray | None = None) -> IKResult:
            return IKResult(True, np.array([T_world_tcp[0, 3], -1.0 if q_seed is None else q_seed[0]]))

    OneAtATime.__abstractmethods__ = frozenset()
    T = np.stack([np.eye(4)] * 3)
    T[:, 0, 3] = [1.0, 2.0, 3.0]
    assert [r.q.tolist() for r in OneAtATime().ik_many("a", T)] == [[1, -1], [2, -1], [3, -1]]
    seeds = np.array([[7.0, 0], [8, 0], [9, 0]])
    assert [r.q[1] for r in OneAtATime().ik_many("a", T, seeds)] == [7, 8, 9]


@pytest.mark.parametrize("arm", ["left", "right"])
def test_batched_fk_and_jacobian_match_pinocchio(robot: NextagePyBullet, arm: str) -> None:
    lo, hi = robot.joint_limits(arm)
    qs = np.random.default_rng(5).uniform(lo, hi, size=(25, len(lo)))
    T, J = _ChainSolver(robot.kin, robot.kin.chain(arm)).fk_jac(qs)
    for k, q in enumerate(qs):
        assert np.allclose(T[k], robot.fk(arm, q), atol=1e-12)
        # pinocchio's LOCAL_WORLD_ALIGNED Jacobian: world axes, about the TCP
        assert np.allclose(J[k], robot.jacobian(arm, q), atol=1e-12)


def test_rotation_log_is_exact_near_pi_and_near_zero() -> None:
    rng = np.random.default_rng(2)
    axes = rng.normal(size=(60, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    # every Shepperd case: angles near pi about each axis, tiny angles, and random ones
    angles = np.concatenate([np.pi - np.logspace(-9, -1, 20), np.logspace(-10, -2, 20), rng.uniform(0, np.pi, 20)])
    R = Rotation.from_rotvec(axes * angles[:, None]).as_matrix()
    w = _rotvec(R)
    ref = Rotation.from_matrix(R).as_rotvec()
    assert np.allclose(w, ref, atol=1e-9)
    assert np.allclose(np.linalg.norm(w, axis=1), angles, atol=1e-9)
    assert np.allclose(_rotvec(np.eye(3)[None]), 0.0)


def test_rows_of_one_target_stop_once_a_preferred_row_converges(robot: NextagePyBullet) -> None:
    solver = _ChainSolver(robot.kin, robot.kin.chain("right"))
    T = _reachable(robot, "right", 30, seed=9)
    lo, hi = robot.joint_limits("right")
    starts = np.random.default_rng(1).uniform(lo, hi, size=(30 * 4, len(lo)))
    rows_T = np.repeat(T, 4, axis=0)
    ok_all, q_all, _, _ = solver.dls(rows_T, starts)
    ok, q, _, _ = solver.dls(rows_T, starts, group=4)
    ok_all, ok = ok_all.reshape(30, 4), ok.reshape(30, 4)
    assert ok.any(axis=1).tolist() == ok_all.any(axis=1).tolist()
    assert ok.sum() < ok_all.sum()  # later rows of solved targets stopped
    first = np.argmax(ok_all, axis=1)
    solved = ok_all.any(axis=1)
    assert np.array_equal(np.argmax(ok, axis=1)[solved], first[solved])
    r = np.flatnonzero(solved)
    assert np.allclose(q.reshape(30, 4, -1)[r, first[r]], q_all.reshape(30, 4, -1)[r, first[r]], atol=0)
