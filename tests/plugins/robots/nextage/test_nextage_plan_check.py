"""The independent PyBullet re-check of plans: what it catches, what it allows, how densely it looks."""

from __future__ import annotations

import numpy as np
import pybullet
import pytest

from asmteach.core.arm.plan_check import CheckedArm, PlanCheck, densify_by_reach
from asmteach.core.arm.plan_checker import PlanChecker, recheck_plan
from asmteach.core.arm.sim import PyBulletWorld
from asmteach.core.errors import UserError
from asmteach.core.models import GripperEvent, PartSpec, Plan, PlanSegment, Primitive, SolidSpec, TablePlane, Trajectory
from asmteach.core.parts import build_part
from asmteach.plugins.planners.regrasp.motions import cartesian_path
from asmteach.plugins.robots.nextage.robot import NextagePyBullet

TABLE = TablePlane(height=0.0)


@pytest.fixture(scope="module")
def robot():
    r = NextagePyBullet({"ik": {"max_starts": 4}}, seed=0)
    yield r
    r.close()


def _block(name: str, size: tuple[float, float, float]):
    """A box part whose frame sits at the centre of its bottom face (it rests on the table at z = 0)."""
    pose = np.eye(4)
    pose[2, 3] = 0.5 * size[2]
    return build_part(PartSpec(name=name, solid=SolidSpec(add=[Primitive(shape="box", size=list(size), pose=pose)])))


def _at(x: float, y: float, z: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = [x, y, z]
    return T


def _tcp_at(robot: NextagePyBullet, x: float, y: float, z: float) -> np.ndarray:
    """The left hand's home orientation (pointing down) at another place."""
    T = robot.fk("left", robot.home("left"))
    T[:3, 3] = [x, y, z]
    return T


def _line(robot: NextagePyBullet, q_from: np.ndarray, T_to: np.ndarray) -> np.ndarray:
    path, why = cartesian_path(robot, "left", q_from, T_to, 0.004)
    assert path is not None, why
    return path


def _segment(robot: NextagePyBullet, label: str, path: np.ndarray, dt: float = 0.05) -> PlanSegment:
    path = np.atleast_2d(path)
    return PlanSegment(
        label=label,
        trajectory=Trajectory(
            arm="left",
            joint_names=robot.joint_names("left"),
            times=(np.arange(len(path)) * dt).tolist(),
            positions=path,
        ),
    )


def _joint_line(q0: np.ndarray, q1: np.ndarray, n: int = 5) -> np.ndarray:
    s = np.linspace(0.0, 1.0, n)[:, None]
    return q0[None] + s * (q1 - q0)[None]


def _arms(robot: NextagePyBullet, *, hands: bool = True) -> dict[str, CheckedArm]:
    return {
        a: CheckedArm(
            tuple(s.joints),
            s.tcp_link,
            tuple(s.gripper.finger_joints),
            tuple(s.gripper.open_values),
            tuple(s.hand_links) if hands else (),
        )
        for a, s in robot._arms.items()
    }


def test_a_hand_driven_through_the_table_is_reported_with_its_segment_and_pair(robot) -> None:
    home = robot.home("left")
    high = _line(robot, home, _tcp_at(robot, 0.30, 0.22, 0.25))
    # TCP 10 mm below the table top: the fingertips (17.5 mm below the TCP) end 27.5 mm deep
    down = _line(robot, high[-1], _tcp_at(robot, 0.30, 0.22, -0.010))
    plan = Plan(
        segments=[_segment(robot, "move to pre-grasp 0 of box", high), _segment(robot, "approach grasp 0", down)]
    )
    check = robot.verify_plan(plan, {}, TABLE)
    assert not check.ok
    assert {c.segment for c in check.collisions} == {1}
    assert all(c.label == "approach grasp 0" for c in check.collisions)
    pairs = {(c.a, c.b): c for c in check.collisions}
    for finger in ("LARM_FINGER0_Link", "LARM_FINGER1_Link"):
        assert pairs[(finger, "table")].penetration_m == pytest.approx(0.0275, abs=1.5e-3)
    # contact starts where the fingertips reach the table top: TCP 17.5 mm above it, i.e. 232.5 mm down
    first = min(pairs[("LARM_FINGER0_Link", "table")].time_s, pairs[("LARM_FINGER1_Link", "table")].time_s)
    times = np.asarray(plan.segments[1].trajectory.times)
    z = np.array([robot.fk("left", q)[2, 3] for q in down])
    z_first = np.interp(first, times, z)
    assert z_first == pytest.approx(0.0175, abs=0.006)
    assert "approach grasp 0" in check.summary()


def test_a_free_motion_high_above_the_table_is_clean(robot) -> None:
    home = robot.home("left")
    target = robot.ik("left", _tcp_at(robot, 0.35, 0.30, 0.30), q_seed=home)
    assert target.success
    plan = Plan(
        segments=[
            _segment(robot, "move high", np.stack([home, target.q]), dt=1.0),
            _segment(robot, "left arm home", np.stack([target.q, home]), dt=1.0),
        ]
    )
    check = robot.verify_plan(plan, {"post": (_block("post", (0.04, 0.04, 0.10)), _at(0.45, -0.2))}, TABLE)
    assert check.ok, check.summary()
    assert check.collisions == [] and check.warnings == []
    assert 0.0 < check.min_distance_m <= 0.02
    assert check.n_configurations_checked > 2 * 20  # both swings were subdivided


def test_a_joint_space_swing_that_folds_the_wrist_into_the_forearm_is_reported(robot) -> None:
    home = robot.home("left")
    target = robot.ik("left", _tcp_at(robot, 0.30, 0.25, 0.35), q_seed=home)
    assert target.success
    plan = Plan(segments=[_segment(robot, "move high", np.stack([home, target.q]), dt=1.0)])
    check = robot.verify_plan(plan, {}, TABLE)
    pairs = {(c.a, c.b) for c in check.collisions}
    assert ("LARM_JOINT2_Link", "LARM_GRIPPER_Link") in pairs
    assert all(c.segment == 0 for c in check.collisions)
    # the planner's own model (pinocchio + fcl) agrees on the pair
    dense = densify_by_reach(np.array([0.0, 1.0]), np.stack([home, target.q]), np.ones(6), 0.01)[1]
    hits = robot.in_collision("left", dense)
    assert ("LARM_JOINT2_Link", "LARM_GRIPPER_Link") in robot.collision_report("left", dense[int(np.argmax(hits))])


def _carry_plan(robot: NextagePyBullet, width: float) -> Plan:
    """Pick the box under the left hand, lift it, carry it sideways through the post."""
    home = robot.home("left")
    down = _line(robot, home, _tcp_at(robot, 0.25, 0.20, 0.04))
    up = _line(robot, down[-1], _tcp_at(robot, 0.25, 0.20, 0.12))
    over = _line(robot, up[-1], _tcp_at(robot, 0.25, -0.02, 0.12))
    return Plan(
        segments=[
            _segment(robot, "approach grasp 0", down),
            PlanSegment(
                label="close on box", gripper=GripperEvent(arm="left", action="close", width=width, attach="box")
            ),
            _segment(robot, "lift box", up),
            _segment(robot, "carry box to the post", over),
        ]
    )


def _carry_parts() -> dict:
    return {
        "box": (_block("box", (0.04, 0.04, 0.06)), _at(0.25, 0.20)),
        "post": (_block("post", (0.04, 0.04, 0.20)), _at(0.25, 0.05)),
    }


def test_a_held_box_carried_through_a_part_is_reported_but_the_fingers_holding_it_are_not(robot) -> None:
    # closing on 36 mm squeezes the 40 mm box by 2 mm per finger: the intended contact of a firm grasp
    plan = _carry_plan(robot, width=0.036)
    check = robot.verify_plan(plan, _carry_parts(), TABLE)
    assert not check.ok
    assert {c.segment for c in check.collisions} == {3}, check.collisions
    pairs = {(c.a, c.b) for c in check.collisions}
    assert ("box", "post") in pairs
    assert not any("box" in (c.a, c.b) and "FINGER" in c.a + c.b for c in check.collisions)
    assert PlanCheck.model_validate_json(check.model_dump_json()) == check  # writes to and reads from JSON
    box_post = next(c for c in check.collisions if (c.a, c.b) == ("box", "post"))
    assert box_post.penetration_m > 0.01  # it goes right through, not grazing
    # the same replay with no hand links allowed to touch the held part: the squeeze is reported
    st = robot.settings
    strict = recheck_plan(
        robot.urdf,
        robot.T_world_base,
        plan,
        _carry_parts(),
        _arms(robot, hands=False),
        {a: robot.home(a) for a in robot.arms},
        table_center=st.table_center,
        table_size=st.table_size,
        table_height=0.0,
        skip_pairs=robot.checker.disabled,
    )
    squeezed = [c for c in strict.collisions if c.b == "box" and "FINGER" in c.a]
    assert {c.segment for c in squeezed} >= {1, 2}
    assert max(c.penetration_m for c in squeezed) == pytest.approx(0.002, abs=5e-4)


def test_a_held_box_may_touch_the_table_only_where_the_rules_allow(robot) -> None:
    plan = _carry_plan(robot, width=0.04)
    plan.segments = plan.segments[:3]
    parts = _carry_parts()
    assert robot.verify_plan(plan, parts, TABLE).ok
    # the box sunk 3 mm into the table where it is grasped: fine while closing and lifting, not when carried
    parts["box"] = (parts["box"][0], _at(0.25, 0.20, -0.003))
    plan.segments[2].label = "carry box"
    check = robot.verify_plan(plan, parts, TABLE)
    assert [(c.segment, c.a, c.b) for c in check.collisions] == [(2, "box", "table")]
    assert check.collisions[0].penetration_m == pytest.approx(0.003, abs=5e-4)
    assert check.collisions[0].time_s == 0.0


def test_a_part_let_go_just_above_the_table_lands_on_it(robot) -> None:
    # the box is put down 1 mm up (the planner's release gap), or 10 mm up (a real drop the check keeps)
    for gap, z_after in ((0.001, 0.0), (0.010, 0.010)):
        plan = _carry_plan(robot, width=0.04)
        lowered = _line(
            robot, np.asarray(plan.segments[2].trajectory.positions)[-1], _tcp_at(robot, 0.25, 0.20, 0.04 + gap)
        )
        plan.segments[3:] = [
            _segment(robot, "place box", lowered),
            PlanSegment(label="release box", gripper=GripperEvent(arm="left", action="open")),
        ]
        world = PyBulletWorld(robot.urdf, robot.T_world_base)
        try:
            st = robot.settings
            checker = PlanChecker(
                world,
                _arms(robot),
                table_center=st.table_center,
                table_size=st.table_size,
                table_height=0.0,
                skip_pairs=robot.checker.disabled,
            )
            assert checker.check(plan, _carry_parts(), {a: robot.home(a) for a in robot.arms}).ok
            pos, _ = world.p.getBasePositionAndOrientation(world.parts["box"][0])
            assert pos[2] - 0.03 == pytest.approx(z_after, abs=2e-4)  # the base frame is the box's centre
        finally:
            world.close()


def test_densification_keeps_every_point_within_the_resolution_on_a_fast_swing(robot) -> None:
    world = PyBulletWorld(robot.urdf, robot.T_world_base)
    try:
        st = robot.settings
        world.reset_world(st.table_center, st.table_size, 0.0, {})
        checker = PlanChecker(
            world,
            _arms(robot),
            table_center=st.table_center,
            table_size=st.table_size,
            table_height=0.0,
            skip_pairs=robot.checker.disabled,
        )
        names = robot.joint_names("left")
        ids = world.joint_ids(names)
        q0 = robot.home("left")
        q1 = q0.copy()
        q0[0], q1[0] = -0.7, 0.5  # the shoulder swings 1.2 rad in 0.1 s
        world.set_joints(names, q0)
        times, dense = densify_by_reach(np.array([0.0, 0.1]), np.stack([q0, q1]), checker.joint_reach(ids, {}), 0.005)
        assert np.all(np.diff(times) > 0) and times[0] == 0.0 and times[-1] == 0.1
        np.testing.assert_allclose(dense[[0, -1]], [q0, q1])
        corners = []
        for q in dense:  # every corner of every box shape of the robot, in the world, from PyBullet
            world.set_joints(names, q)
            pts = []
            for link in range(world.p.getNumJoints(world.robot)):
                st_l = world.p.getLinkState(world.robot, link, computeForwardKinematics=True)
                R = np.reshape(world.p.getMatrixFromQuaternion(st_l[1]), (3, 3))
                for sh in world.p.getCollisionShapeData(world.robot, link):
                    if sh[2] != pybullet.GEOM_BOX:
                        continue
                    Rl = np.reshape(world.p.getMatrixFromQuaternion(sh[6]), (3, 3))
                    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
                    local = np.asarray(sh[5]) + (signs * 0.5 * np.asarray(sh[3])) @ Rl.T
                    pts.append(np.asarray(st_l[0]) + local @ R.T)
            corners.append(np.vstack(pts))
        step = np.linalg.norm(np.diff(np.stack(corners), axis=0), axis=2).max(axis=1)
        assert step.max() <= 0.005 + 1e-9
        assert step.max() > 0.002  # the bound is conservative, not absurd
        # the fingertips travel about 1.2 rad x their distance from the shoulder axis; enough samples for that
        arc = np.linalg.norm(np.diff(np.stack(corners), axis=0), axis=2).max(axis=1).sum()
        assert len(dense) >= arc / 0.005
    finally:
        world.close()


def test_densify_by_reach_keeps_waypoints_and_splits_by_the_worst_point() -> None:
    q = np.array([[0.0, 0.0], [0.1, 0.0], [0.1, 0.0], [0.1, 0.3]])
    t, d = densify_by_reach(np.array([0.0, 1.0, 2.0, 3.0]), q, np.array([0.5, 0.1]), 0.01)
    # 0.1 rad x 0.5 m = 50 mm -> 5 steps; a standstill -> 1; 0.3 rad x 0.1 m = 30 mm -> 3
    assert len(d) == 5 + 1 + 3 + 1
    for w in q:
        assert np.any(np.all(np.isclose(d, w), axis=1))
    np.testing.assert_allclose(t, [0, 0.2, 0.4, 0.6, 0.8, 1, 2, 2 + 1 / 3, 2 + 2 / 3, 3])
    moved = np.abs(np.diff(d, axis=0)) @ np.array([0.5, 0.1])
    assert moved.max() <= 0.01 + 1e-12


def test_bad_input_says_what_to_fix(robot) -> None:
    plan = Plan(
        segments=[PlanSegment(label="close on ghost", gripper=GripperEvent(arm="left", action="close", attach="ghost"))]
    )
    with pytest.raises(UserError, match="attaches 'ghost'"):
        robot.verify_plan(plan, {}, TABLE)
    with pytest.raises(UserError, match="resolution must be > 0"):
        robot.verify_plan(Plan(), {}, TABLE, resolution=0.0)
    bad = Plan(
        segments=[
            PlanSegment(
                label="x",
                trajectory=Trajectory(arm="middle", joint_names=["LARM_JOINT0"], times=[0.0], positions=[[0.0]]),
            )
        ]
    )
    with pytest.raises(UserError, match="arm 'middle'"):
        robot.verify_plan(bad, {}, TABLE)


@pytest.mark.slow
def test_a_real_peg_in_hole_plan_is_collision_free_when_rechecked(peg_in_hole_plan) -> None:
    """The plan of tests/plugins/planners/regrasp/test_regrasp_assembly.py, re-checked at 5 mm."""
    p = peg_in_hole_plan
    a, b, T_a, T_b, robot, res = p.a, p.b, p.T_a, p.T_b, p.robot, p.result
    assert res.success, res.reason
    check = robot.verify_plan(res.plan, {a.name: (a, T_a), b.name: (b, T_b)}, TABLE)
    assert check.ok, check.summary()
    assert check.warnings == []
    n_traj = sum(s.trajectory is not None for s in res.plan.segments)
    assert check.n_configurations_checked > n_traj * 10
    assert check.min_distance_m > -check.tolerance_m
