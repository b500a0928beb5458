"""Physical hold check in PyBullet: close, lift 10 cm, hold 2 s under a light shake.

The gripper is built from the :class:`HandSpec`: a palm box (the multibody's
base, its frame is the TCP frame) and two finger links on prismatic joints
along the TCP y axis (coupled by a gear constraint, so they close symmetrically),
each a finger box with a 1 mm pad box on its inner face.
The palm is driven kinematically through a constraint to the world (as a
robot arm would hold it); the part is a free dynamic body held by friction
alone: no constraint ever ties it to the gripper.

Sequence (world frame, z up, metres, seconds): the grasp is placed top-down
(TCP z along world -z) with the part in the air and gravity off; the fingers
close with ``hand.max_force`` newtons each; gravity is switched on; the palm
lifts ``lift`` metres in 1 s, then holds for ``hold`` seconds while shaking
horizontally (``shake_amplitude`` metres at ``shake_hz``). The grasp *holds*
when the part rose with the palm (at least 80 % of the lift) and both fingers
still touch it at the end (a contact point, or the finger within 0.5 mm of
it). Bullet multiplies the friction coefficients of two touching bodies; the
part gets 1.0, so ``friction`` is the pad-part value (and the pads' torsional
friction follows from it and the pad size).
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet

from asmteach.core import geometry
from asmteach.core.convex_pieces import decompose
from asmteach.core.hand_geometry import hand_boxes
from asmteach.core.interfaces import PartModel
from asmteach.core.models import Grasp, HandSpec

__all__ = ["HoldResult", "HoldSimulator"]

_PAD_THICKNESS = 0.001
_CLOSE_S = 0.6
_SETTLE_S = 0.3
_CLOSE_SPEED = 0.1
"""Finger closing speed, m/s."""
_CLOSE_STEP = 1e-4
"""Most a finger moves per simulation step while it closes and the grip settles, metres. At 0.1 m/s and
1/240 s a pad moved 0.42 mm per step, a sixth of a 2.5 mm plate: it met the plate already inside it, the
solver (100 iterations over some 60 contacts of the pieces under one pad) did not push it back out, contacts
stayed 2 mm deep and the jaws closed through: 8/15 pinches of a plate held, 15/15 at 1 ms steps."""
_LIFT_S = 1.0


@dataclass
class HoldResult:
    """Outcome of one lift-and-shake trial."""

    held: bool
    lift: float
    """How far the part rose (metres)."""
    drift: float
    """Part translation relative to the TCP between the start of the lift and the end (metres)."""
    drift_angle: float
    """Part rotation relative to the TCP over the same span (radians)."""
    reason: str = ""


def _quat(T: np.ndarray) -> list[float]:
    return geometry.to_quat(T).tolist()


def _principal_inertia(part: PartModel, mass: float) -> tuple[np.ndarray, np.ndarray]:
    """``(R_part_inertia, moments)``: principal axes (columns, part frame) and moments (kg m^2) of the part's
    inertia about its ``center_of_mass``, for its mesh filled uniformly to ``mass`` kilograms."""
    mesh = part.mesh
    volume = float(mesh.volume)
    if not mesh.is_volume or volume <= 0.0:  # an open mesh has no inertia tensor: a solid box of its extents
        e = np.asarray(mesh.extents, dtype=float)
        return np.eye(3), mass / 12.0 * ((e**2).sum() - e**2)
    # trimesh's tensor is about the mesh's own centre of mass at its density; the parallel-axis theorem moves it
    d = np.asarray(part.center_of_mass, dtype=float) - np.asarray(mesh.center_mass, dtype=float)
    own = np.asarray(mesh.moment_inertia, dtype=float) * (mass / float(mesh.mass))
    inertia = own + mass * (d @ d * np.eye(3) - np.outer(d, d))
    moments, axes = np.linalg.eigh(inertia)
    if np.linalg.det(axes) < 0.0:  # a rotation, not a reflection
        axes[:, 2] *= -1.0
    return axes, np.maximum(moments, 1e-12)


class HoldSimulator:
    """One PyBullet DIRECT client for many hold checks of one part; use as a context manager."""

    def __init__(
        self,
        hand: HandSpec,
        part: PartModel,
        *,
        friction: float = 0.5,
        timestep: float = 1.0 / 240.0,
        hand_mass: float = 0.8,
        finger_mass: float = 0.05,
        min_part_mass: float = 0.02,
    ) -> None:
        self.hand = hand
        self.part = part
        self.friction = float(friction)
        self.dt = float(timestep)
        self.hand_mass = hand_mass
        self.finger_mass = finger_mass
        # Bullet cannot keep a part of a gram or two from being pushed into 40 N fingers (the mass ratio): the
        # jaws close through it and it then hangs on the interpenetration. Such parts are simulated at this
        # mass, which only makes holding them harder (more weight for the same friction).
        self.min_part_mass = float(min_part_mass)
        self.client = pybullet.connect(pybullet.DIRECT)
        # the project's one convex decomposition (exact for solids and CAD meshes), written once as OBJ
        self._tmp = tempfile.TemporaryDirectory(prefix="asmteach_hold_")
        self._obj_path = str(Path(self._tmp.name) / "pieces.obj")
        Path(self._obj_path).write_text(decompose(part).obj(), encoding="utf-8")

    def close(self) -> None:
        """Disconnect the simulator."""
        if self.client >= 0:
            pybullet.disconnect(self.client)
            self.client = -1
            self._tmp.cleanup()

    def __enter__(self) -> HoldSimulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ bodies
    def _spawn_part(self, T_world_part: np.ndarray) -> int:
        """The part as ONE rigid body whose collision shape is the compound of its convex pieces.

        A multibody with one fixed link per piece (how this check built parts before) lets the pads sink
        through a thin part: on a 2.65 mm plate of 429 pieces the contacts were 2-4.5 mm deep 0.05 s into
        the close, their normals flipping sign, and the jaws met inside the plate (equal link masses did
        no better, so it is the articulation, not the slivers' tiny masses). One body with a compound
        shape is what a rigid part is, and how :class:`asmteach.core.arm.sim.PyBulletWorld` spawns parts.
        Its mass properties are the mesh's (uniform density), about the part's centre of mass.
        """
        c = self.client
        mass = max(self.part.mass, self.min_part_mass)
        com = np.asarray(self.part.center_of_mass, dtype=float)
        R_part_inertia, principal = _principal_inertia(self.part, mass)
        T_part_inertia = geometry.from_rotation(R_part_inertia, com)
        # PyBullet makes one convex hull per object of an OBJ file: a compound of the pieces
        shape = pybullet.createCollisionShape(pybullet.GEOM_MESH, fileName=self._obj_path, physicsClientId=c)
        body = pybullet.createMultiBody(
            baseMass=mass,
            baseCollisionShapeIndex=shape,
            basePosition=T_world_part[:3, 3].tolist(),
            baseOrientation=_quat(T_world_part),
            baseInertialFramePosition=com.tolist(),
            baseInertialFrameOrientation=_quat(T_part_inertia),
            physicsClientId=c,
        )
        # exact convex pieces collide without a margin (as PyBulletWorld's parts: its CONTACT_MARGIN)
        pybullet.changeDynamics(
            body,
            -1,
            lateralFriction=1.0,
            spinningFriction=1.0,
            localInertiaDiagonal=principal.tolist(),
            collisionMargin=0.0,
            physicsClientId=c,
        )
        self._T_part_inertia = T_part_inertia
        return body

    def _part_pose(self, body: int) -> np.ndarray:
        pos, orn = pybullet.getBasePositionAndOrientation(body, physicsClientId=self.client)
        # PyBullet reports the inertial frame's pose
        return geometry.from_quat(orn, pos) @ geometry.invert(self._T_part_inertia)

    def _spawn_gripper(self, T_world_tcp: np.ndarray, opening: float) -> int:
        c = self.client
        boxes = {b.name: b for b in hand_boxes(self.hand, 0.0)}
        palm = boxes["palm"]
        palm_shape = pybullet.createCollisionShape(
            pybullet.GEOM_BOX,
            halfExtents=(0.5 * palm.size).tolist(),
            collisionFramePosition=palm.center.tolist(),
            physicsClientId=c,
        )
        pad = np.array([self.hand.pad_size[0], _PAD_THICKNESS, self.hand.pad_size[1]])
        finger_shapes = []
        for name, sign in (("finger0", -1.0), ("finger1", 1.0)):
            f = boxes[name]
            # The finger body sits behind a 1 mm pad whose face is the jaw plane (y = 0 at zero opening).
            body_centre = f.center + np.array([0.0, sign * _PAD_THICKNESS, 0.0])
            pad_centre = np.array([0.0, sign * 0.5 * _PAD_THICKNESS, 0.0])
            finger_shapes.append(
                pybullet.createCollisionShapeArray(
                    shapeTypes=[pybullet.GEOM_BOX, pybullet.GEOM_BOX],
                    halfExtents=[(0.5 * f.size).tolist(), (0.5 * pad).tolist()],
                    collisionFramePositions=[body_centre.tolist(), pad_centre.tolist()],
                    physicsClientId=c,
                )
            )
        body = pybullet.createMultiBody(
            baseMass=self.hand_mass,
            baseCollisionShapeIndex=palm_shape,
            basePosition=T_world_tcp[:3, 3].tolist(),
            baseOrientation=_quat(T_world_tcp),
            linkMasses=[self.finger_mass, self.finger_mass],
            linkCollisionShapeIndices=finger_shapes,
            linkVisualShapeIndices=[-1, -1],
            linkPositions=[[0, 0, 0], [0, 0, 0]],
            linkOrientations=[[0, 0, 0, 1]] * 2,
            linkInertialFramePositions=[[0, 0, 0]] * 2,
            linkInertialFrameOrientations=[[0, 0, 0, 1]] * 2,
            linkParentIndices=[0, 0],
            linkJointTypes=[pybullet.JOINT_PRISMATIC] * 2,
            linkJointAxis=[[0, 1, 0], [0, 1, 0]],
            physicsClientId=c,
        )
        for j, q in ((0, -0.5 * opening), (1, 0.5 * opening)):
            pybullet.resetJointState(body, j, q, physicsClientId=c)
        # The jaws are coupled, as in a real parallel gripper's linkage: q0 + q1 = 0
        # keeps the part centred instead of letting both fingers drift along y together.
        gear = pybullet.createConstraint(
            body, 0, body, 1, pybullet.JOINT_GEAR, [0, 1, 0], [0, 0, 0], [0, 0, 0], physicsClientId=c
        )
        pybullet.changeConstraint(gear, gearRatio=1.0, maxForce=1000.0, erp=0.2, physicsClientId=c)
        # Torsional friction of a flat pad: a uniformly pressed disc of radius a resists
        # (2/3) mu F a; a is taken as half the radius of the pad's equal-area disc, since the
        # contact patch rarely covers the whole pad. Bullet's contacts between a box and a
        # convex mesh are often single points, which would resist no twisting otherwise.
        a = 0.5 * float(np.sqrt(self.hand.pad_size[0] * self.hand.pad_size[1] / np.pi))
        spinning = (2.0 / 3.0) * self.friction * a
        for link in (0, 1):
            pybullet.changeDynamics(
                body,
                link,
                lateralFriction=self.friction,
                spinningFriction=spinning,
                frictionAnchor=True,
                physicsClientId=c,
            )
        return body

    # ------------------------------------------------------------------ trial
    def check(
        self,
        grasp: Grasp,
        *,
        lift: float = 0.10,
        hold: float = 2.0,
        shake_amplitude: float = 0.01,
        shake_hz: float = 2.0,
        clearance: float = 0.002,
    ) -> HoldResult:
        """Run one lift-and-shake trial of ``grasp`` (part frame) and report whether the part stayed held."""
        c = self.client
        pybullet.resetSimulation(physicsClientId=c)
        # a finer step while the fingers close and the grip settles (see _CLOSE_STEP); the lift and shake,
        # with the pads already resting on the part, run at ``timestep``
        close_dt = min(self.dt, _CLOSE_STEP / _CLOSE_SPEED)
        pybullet.setPhysicsEngineParameter(fixedTimeStep=close_dt, numSolverIterations=100, physicsClientId=c)
        pybullet.setGravity(0, 0, 0, physicsClientId=c)
        # Top-down: TCP z along world -z, jaw axis along world x, TCP 0.5 m up.
        R_world_tcp = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
        T_world_tcp = geometry.from_rotation(R_world_tcp, [0.0, 0.0, 0.5])
        T_world_part = T_world_tcp @ geometry.invert(grasp.T_part_tcp)
        part = self._spawn_part(T_world_part)
        opening = min(grasp.width + 2.0 * clearance, self.hand.max_width)
        gripper = self._spawn_gripper(T_world_tcp, opening)
        orn = _quat(T_world_tcp)
        cid = pybullet.createConstraint(
            gripper, -1, -1, -1, pybullet.JOINT_FIXED, [0, 0, 0], [0, 0, 0],
            T_world_tcp[:3, 3].tolist(), childFrameOrientation=orn, physicsClientId=c,
        )  # fmt: skip
        pybullet.changeConstraint(cid, maxForce=2000.0, physicsClientId=c)
        for j in (0, 1):
            pybullet.setJointMotorControl2(
                gripper, j, pybullet.POSITION_CONTROL, targetPosition=0.0,
                force=self.hand.max_force, maxVelocity=_CLOSE_SPEED, physicsClientId=c,
            )  # fmt: skip
        self._run(_CLOSE_S, close_dt)
        pybullet.setGravity(0, 0, -9.81, physicsClientId=c)
        self._run(_SETTLE_S, close_dt)
        pybullet.setPhysicsEngineParameter(fixedTimeStep=self.dt, physicsClientId=c)
        T_tcp_part0 = geometry.invert(T_world_tcp) @ self._part_pose(part)
        z0 = self._part_pose(part)[2, 3]
        start = T_world_tcp[:3, 3].copy()
        steps = round(_LIFT_S / self.dt)
        for k in range(1, steps + 1):
            pos = start + np.array([0.0, 0.0, lift * k / steps])
            self._drive(cid, pos, orn)
            pybullet.stepSimulation(physicsClientId=c)
        top = start + np.array([0.0, 0.0, lift])
        steps = round(hold / self.dt)
        for k in range(1, steps + 1):
            t = k * self.dt
            dx = shake_amplitude * np.sin(2.0 * np.pi * shake_hz * t)
            dy = 0.5 * shake_amplitude * np.sin(2.0 * np.pi * shake_hz * t + 0.7)
            pos = top + np.array([dx, dy, 0.0])
            self._drive(cid, pos, orn)
            pybullet.stepSimulation(physicsClientId=c)
        pos, _ = pybullet.getBasePositionAndOrientation(gripper, physicsClientId=c)
        T_world_tcp_end = geometry.from_rotation(R_world_tcp, pos)
        T_world_part_end = self._part_pose(part)
        T_tcp_part1 = geometry.invert(T_world_tcp_end) @ T_world_part_end
        risen = float(T_world_part_end[2, 3] - z0)
        drift = geometry.translation_distance(T_tcp_part0, T_tcp_part1)
        angle = geometry.rotation_distance(T_tcp_part0, T_tcp_part1)
        # Touching: a contact point, or the pad within 0.5 mm of the part (Bullet's manifold of a thin part
        # squeezed between two pads can be empty at a given step while the part hangs in the grip).
        touching = [
            len(pybullet.getContactPoints(gripper, part, linkIndexA=j, physicsClientId=c)) > 0
            or len(pybullet.getClosestPoints(gripper, part, 5e-4, linkIndexA=j, physicsClientId=c)) > 0
            for j in (0, 1)
        ]
        # The jaws closed to under half the grasp's width: they went through the part, whatever it did after.
        q = [pybullet.getJointState(gripper, j, physicsClientId=c)[0] for j in (0, 1)]
        through = (q[1] - q[0]) < 0.5 * grasp.width
        held = risen >= 0.8 * lift and all(touching) and not through
        reason = (
            ""
            if held
            else (
                "dropped"
                if risen < 0.8 * lift
                else "fingers closed through the part"
                if through
                else "lost contact with a finger"
            )
        )
        return HoldResult(held=held, lift=risen, drift=drift, drift_angle=angle, reason=reason)

    def _drive(self, constraint: int, position: np.ndarray, orientation: list[float]) -> None:
        """Move the palm's world constraint to a pose (the caller steps the simulation)."""
        pybullet.changeConstraint(
            constraint,
            jointChildPivot=position.tolist(),
            jointChildFrameOrientation=orientation,
            maxForce=2000.0,
            physicsClientId=self.client,
        )

    def _run(self, seconds: float, dt: float) -> None:
        for _ in range(round(seconds / dt)):
            pybullet.stepSimulation(physicsClientId=self.client)
