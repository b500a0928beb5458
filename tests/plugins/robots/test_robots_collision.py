"""Self and world collisions of the Nextage: known contacts, free home, parts, held part, clearance."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from asmteach.core.interfaces import Obstacle, PartModel
from asmteach.core.models import PartSpec, Primitive, SolidSpec
from asmteach.plugins.robots.nextage.robot import NextagePyBullet


@pytest.fixture()
def robot() -> NextagePyBullet:
    with NextagePyBullet({}) as r:
        yield r


def test_home_is_free_and_known_contacts_are_found(robot: NextagePyBullet) -> None:
    for arm in robot.arms:
        assert not robot.in_collision(arm, robot.home(arm)[None])[0]
    # all-zero: the hand is inside the upper stand of the WAIST (facts, section 8)
    pairs = robot.collision_report("left", np.zeros(6))
    assert ("LARM_JOINT4_Link", "WAIST") in pairs and ("LARM_JOINT5_Link", "WAIST") in pairs
    # NextageClient off pose: upper arm against the shoulder cap of the chest
    off = np.radians([-25.0, -140.0, -150.0, -45.0, 0.0, 0.0])
    off[1] = robot.joint_limits("left")[0][1]
    assert ("LARM_JOINT1_Link", "CHEST_JOINT0_Link") in robot.collision_report("left", off)
    assert robot.in_collision("left", np.stack([robot.home("left"), np.zeros(6), off])).tolist() == [False, True, True]
    # the batched report, one pass over all three, says what each single report says
    qs = np.stack([robot.home("left"), np.zeros(6), off])
    assert robot.collision_reports("left", qs) == [robot.collision_report("left", q) for q in qs]
    assert robot.collision_reports("left", qs)[0] == []


def test_table_and_parts(robot: NextagePyBullet) -> None:
    q = robot.home("left")
    T = robot.fk("left", q)
    low = T.copy()
    low[2, 3] = -0.01  # fingertips 2.75 cm under the table top
    res = robot.ik("left", low, q)
    assert res.success
    assert ("LARM_FINGER0_Link", "table") in robot.collision_report("left", res.q)
    # the open jaw (85 mm) clears a 30 mm cube at the TCP; a 100 mm cube hits the fingers
    T_cube = np.eye(4)
    T_cube[:3, 3] = T[:3, 3]
    robot.set_obstacles([Obstacle("cube", trimesh.creation.box((0.03, 0.03, 0.03)), T_cube)])
    assert not robot.in_collision("left", q[None])[0]
    robot.set_obstacles([Obstacle("cube", trimesh.creation.box((0.1, 0.1, 0.03)), T_cube)])
    pairs = robot.collision_report("left", q)
    assert ("LARM_FINGER0_Link", "cube") in pairs and ("LARM_FINGER1_Link", "cube") in pairs
    T_cube[:3, 3] += [0.0, -0.4, 0.0]
    robot.set_obstacles([Obstacle("cube", trimesh.creation.box((0.1, 0.1, 0.03)), T_cube)])
    assert not robot.in_collision("left", q[None])[0]


def test_held_part_collides_with_the_table_unless_ignored(robot: NextagePyBullet) -> None:
    spec = PartSpec(name="bar", solid=SolidSpec(add=[Primitive(shape="box", size=[0.02, 0.02, 0.3])]))
    mesh = trimesh.creation.box((0.02, 0.02, 0.3))
    part = PartModel(spec=spec, mesh=mesh, mass=0.1, center_of_mass=np.zeros(3))
    q = robot.home("left")
    assert not robot.in_collision("left", q[None])[0]
    T_tcp_part = np.eye(4)
    T_tcp_part[2, 3] = 0.12  # a 30 cm bar held near its top end, pointing down into the table
    robot.attach("left", part, T_tcp_part)
    assert robot.in_collision("left", q[None])[0]
    assert ("held:bar", "table") in robot.collision_report("left", q)
    assert not robot.in_collision("left", q[None], ignore=["table"])[0]
    robot.attach("left", None)
    assert not robot.in_collision("left", q[None])[0]


def test_batch_equals_single_and_clearance(robot: NextagePyBullet) -> None:
    rng = np.random.default_rng(2)
    lo, hi = robot.joint_limits("right")
    qs = rng.uniform(lo, hi, size=(60, 6))
    batch = robot.in_collision("right", qs)
    single = np.array([robot.in_collision("right", q[None])[0] for q in qs])
    assert np.array_equal(batch, single) and 0 < batch.sum() < len(qs)
    home = robot.home("right")
    c = robot.clearance("right", home[None])[0]
    T = robot.fk("right", home)
    # the fingertips are the lowest point: 0.0175 m beyond the TCP along the approach axis
    assert c == pytest.approx(T[2, 3] - 0.0175, abs=2e-3)
    lower = home.copy()
    lower[4] += 0.1
    assert robot.clearance("right", lower[None])[0] != pytest.approx(c, abs=1e-6)


def test_pruned_clearance_equals_every_pair_measured(robot: NextagePyBullet) -> None:
    import fcl

    from asmteach.core.arm.collision_geometry import fcl_transform

    block = trimesh.creation.box((0.08, 0.06, 0.05))
    T = np.eye(4)
    T[:3, 3] = (0.38, -0.12, 0.025)
    robot.set_obstacles([Obstacle("block", block, T)])
    held = np.eye(4)
    held[2, 3] = 0.05
    spec = PartSpec(name="peg", solid=SolidSpec(add=[Primitive(shape="cylinder", radius=0.01, height=0.06)]))
    peg = PartModel(spec=spec, mesh=trimesh.creation.cylinder(0.01, 0.06), mass=0.05, center_of_mass=np.zeros(3))
    robot.attach("right", peg, held)
    lo, hi = robot.joint_limits("right")
    qs = np.random.default_rng(4).uniform(lo, hi, size=(120, 6))
    qs = qs[~robot.in_collision("right", qs)][:40]
    ch = robot.checker
    objs, *_ = ch._pair_set("right", ())
    moving = set(ch.kin.moving_joints("right"))
    mov = [k for k, g in enumerate(objs) if g.joint in moving and g.joint >= 0]
    world = [k for k, g in enumerate(objs) if g.joint < 0]
    poses = ch._poses("right", qs, objs)
    brute = []
    for i in range(len(qs)):
        for k in mov + world:
            objs[k].fcl_obj.setTransform(fcl_transform(poses[i, k]))
        brute.append(
            min(
                max(0.0, fcl.distance(objs[a].fcl_obj, objs[b].fcl_obj, fcl.DistanceRequest(), fcl.DistanceResult()))
                for a in mov
                for b in world
            )
        )
    brute = np.array(brute)
    assert len(qs) > 20 and brute.min() < 0.1 < brute.max()
    assert np.allclose(robot.clearance("right", qs), brute, atol=1e-12)
    assert np.allclose(robot.clearance("right", qs, upto=0.1), np.minimum(brute, 0.1), atol=1e-12)


def test_a_held_part_closes_the_fingers_of_the_collision_model_on_it(robot: NextagePyBullet) -> None:
    kin = robot.kin
    fingers = robot._arms["left"].gripper.finger_joints
    opened = robot._arms["left"].gripper.open_values

    def values() -> list[float]:
        return [float(kin.q_full[kin.model.joints[kin.model.getJointId(j)].idx_q]) for j in fingers]

    spec = PartSpec(name="cube", solid=SolidSpec(add=[Primitive(shape="box", size=[0.03, 0.03, 0.03])]))
    cube = PartModel(spec=spec, mesh=trimesh.creation.box((0.03, 0.03, 0.03)), mass=0.05, center_of_mass=np.zeros(3))
    T = np.eye(4)
    T[2, 3] = 0.02
    q = robot.home("left")
    robot.attach("left", cube, T, width=0.03)
    robot.in_collision("left", q[None])  # the robot's checker takes the scene on when asked about it
    assert values() == pytest.approx([0.015, 0.015])
    T_tcp = robot.fk("left", robot.home("left"))
    # a thin plate (normal along the jaw axis) 10 mm beyond the closed finger's outer face (15 + 10 mm
    # from the TCP) but through the open finger (inner face 42.5 mm out, 10 mm thick)
    plate = trimesh.creation.box((0.2, 0.002, 0.2))
    T_plate = T_tcp.copy()
    T_plate[:3, 3] += T_tcp[:3, 1] * 0.047
    robot.set_obstacles([Obstacle("plate", plate, T_plate)])
    closed_free = not robot.in_collision("left", q[None])[0]
    robot.attach("left", None)
    open_hits = robot.in_collision("left", q[None])[0]
    assert values() == pytest.approx(list(opened))
    assert closed_free and open_hits
    robot.set_obstacles([])


def test_batch_verdict_equals_every_candidate_pair_tested_with_fcl(robot: NextagePyBullet) -> None:
    import fcl
    import pinocchio as pin

    from asmteach.core.arm.collision_geometry import fcl_transform

    # a block and a held peg, so that boxes, cylinders and meshes all meet
    T = np.eye(4)
    T[:3, 3] = (0.35, -0.2, 0.06)
    robot.set_obstacles([Obstacle("block", trimesh.creation.box((0.12, 0.1, 0.12)), T)])
    spec = PartSpec(name="peg", solid=SolidSpec(add=[Primitive(shape="cylinder", radius=0.01, height=0.08)]))
    peg = PartModel(spec=spec, mesh=trimesh.creation.cylinder(0.01, 0.08), mass=0.05, center_of_mass=np.zeros(3))
    held = np.eye(4)
    held[2, 3] = 0.05
    robot.attach("right", peg, held)
    lo, hi = robot.joint_limits("right")
    qs = np.random.default_rng(11).uniform(lo, hi, size=(150, 6))
    ch = robot._binding.checker_at(robot.scene, "right")  # the checker holding the robot's scene
    objs, A, B, _ = ch._pair_set("right", ())
    poses = ch._poses("right", qs, objs)
    kin = ch.kin
    for i in (0, 1):  # the geometry frames are the joints' (pinocchio FK) times their placements
        pin.forwardKinematics(kin.model, kin.data, kin.full_q("right", qs[i]))
        for k, g in enumerate(objs):
            J = np.eye(4) if g.joint < 0 else kin.T_world_base @ kin.data.oMi[g.joint].homogeneous
            assert np.allclose(poses[i, k], J @ g.placement, atol=1e-12)
    brute = np.zeros(len(qs), bool)
    for i in range(len(qs)):
        for a, b in zip(A, B, strict=True):
            objs[a].fcl_obj.setTransform(fcl_transform(poses[i, a]))
            objs[b].fcl_obj.setTransform(fcl_transform(poses[i, b]))
            if fcl.collide(objs[a].fcl_obj, objs[b].fcl_obj, fcl.CollisionRequest(), fcl.CollisionResult()) > 0:
                brute[i] = True
                break
    assert 10 < brute.sum() < len(qs) - 10
    assert np.array_equal(robot.in_collision("right", qs), brute)
