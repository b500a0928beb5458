"""The simulated parallel gripper: close until the fingers touch a part and weld it, open and release.

Acts on a :class:`~asmteach.core.arm.sim.PyBulletWorld` (its robot, parts and ``constraints``/``gears``).
The weld (a fixed constraint from the TCP link to the part) stands in for friction. Units: metres,
radians, seconds, newtons.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pybullet

from asmteach.core.arm.sim import PyBulletWorld, pb_to_pose, pose_to_pb
from asmteach.core.errors import UserError

__all__ = ["GripperJoints", "grip"]


@dataclass
class GripperJoints:
    """A parallel gripper in the simulator: finger joints, their open/closed values and the TCP link."""

    finger_joints: list[str]
    open_values: list[float]
    closed_values: list[float]
    tcp_link: str
    finger_links: list[str]


def grip(
    world: PyBulletWorld,
    arm: str,
    g: GripperJoints,
    close: bool,
    part: str | None,
    force: float,
    speed: float,
    max_time: float = 1.5,
) -> bool:
    """Close ``arm``'s fingers until they touch ``part`` (then weld it to the TCP) or open them and release.

    ``force`` newtons and ``speed`` (m/s or rad/s, the finger joints' unit) drive the fingers for at most
    ``max_time`` simulated seconds. Returns True when closing on ``part`` welded it.
    """
    ids = world.joint_ids(g.finger_joints)
    if not close:
        if arm in world.constraints:
            cid, held = world.constraints.pop(arm)
            world.p.removeConstraint(cid)
            if held in world.parts:
                _finger_contacts(world, g, world.parts[held][0], enable=True)
        for j, v in zip(ids, g.open_values, strict=True):
            world.p.setJointMotorControl2(
                world.robot, j, pybullet.POSITION_CONTROL, targetPosition=v, force=force, maxVelocity=speed
            )
        for _ in range(int(max_time / world.time_step)):
            world.p.stepSimulation()
            if np.allclose(world.get_joints(g.finger_joints), g.open_values, atol=1e-3):
                break
        return False
    body = None
    if part is not None:
        if part not in world.parts:
            raise UserError(f"grip: no part named {part!r} in the simulated world (have {sorted(world.parts)})")
        body = world.parts[part][0]
    finger_idx = [world.link_index[ln] for ln in g.finger_links]
    for j, v in zip(ids, g.closed_values, strict=True):
        world.p.setJointMotorControl2(
            world.robot, j, pybullet.POSITION_CONTROL, targetPosition=v, force=force, maxVelocity=speed
        )
    _couple_fingers(world, arm, g)
    touching = False
    prev = world.get_joints(g.finger_joints)
    for k in range(int(max_time / world.time_step)):
        world.p.stepSimulation()
        if body is not None:
            touching = all(world.p.getContactPoints(world.robot, body, fi, -1) for fi in finger_idx)
            if touching:
                break
        now = world.get_joints(g.finger_joints)
        if k > 10 and np.max(np.abs(now - prev)) < 1e-6:
            break  # the fingers stopped (closed or blocked)
        prev = now
    if body is None or not touching:
        return False
    # Hold the fingers where they touched and weld the part to the TCP so it cannot slip.
    for j, v in zip(ids, world.get_joints(g.finger_joints), strict=True):
        world.p.setJointMotorControl2(
            world.robot, j, pybullet.POSITION_CONTROL, targetPosition=float(v), force=force, maxVelocity=speed
        )
    T_world_tcp = world.link_pose(g.tcp_link)
    pos, orn = world.p.getBasePositionAndOrientation(body)
    T_tcp_com = np.linalg.solve(T_world_tcp, pb_to_pose(pos, orn))
    p_rel, q_rel = pose_to_pb(T_tcp_com)
    # The TCP link's inertial frame is its link frame (URDF inertial origin at 0), as createConstraint expects.
    cid = world.p.createConstraint(
        world.robot,
        world.link_index[g.tcp_link],
        body,
        -1,
        pybullet.JOINT_FIXED,
        [0, 0, 0],
        p_rel,
        [0, 0, 0],
        parentFrameOrientation=q_rel,
    )
    world.p.changeConstraint(cid, maxForce=10000.0)
    # The weld stands in for friction; finger contacts on top of it fight the constraint and make the
    # part creep in the hand during fast motions (millimetres per carry), so they are off while held.
    _finger_contacts(world, g, body, enable=False)
    world.constraints[arm] = (cid, part or "")
    return True


def _couple_fingers(world: PyBulletWorld, arm: str, g: GripperJoints) -> None:
    """Gear the two fingers to move mirror-symmetrically (one motor drives both in a parallel gripper).

    Independent finger servos meet the part one after the other, and the first pushes it across
    the table (a peg lying on its side rolled 2.7 mm and tilted 2.7 deg in the demo's seed 18).
    """
    if arm in world.gears or len(g.finger_links) != 2:
        return
    f0, f1 = (world.link_index[ln] for ln in g.finger_links)
    # The fingers slide along -y and +y of the gripper link: equal joint values, opposite motion.
    cid = world.p.createConstraint(
        world.robot, f0, world.robot, f1, pybullet.JOINT_GEAR, [0, 1, 0], [0, 0, 0], [0, 0, 0]
    )
    world.p.changeConstraint(cid, gearRatio=-1.0, maxForce=200.0, erp=0.2)
    world.gears[arm] = cid


def _finger_contacts(world: PyBulletWorld, g: GripperJoints, body: int, enable: bool) -> None:
    for link in g.finger_links:
        world.p.setCollisionFilterPair(world.robot, body, world.link_index[link], -1, int(enable))
