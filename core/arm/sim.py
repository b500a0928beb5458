"""A PyBullet world for one robot: the robot, the table and parts, trajectory execution.

One PyBullet client per instance (``bullet_client.BulletClient``), never the
global one, so several robots can live in one process. Headless (DIRECT) by
default; GUI when asked and a display exists.

Parts collide as the convex pieces of :func:`asmteach.core.convex_pieces.decompose`
(exact for parametric solids and for meshes the plane split handles, CoACD
with measured fidelity otherwise), loaded as one compound collision shape
from an OBJ file; the visual shape is always the exact mesh.

Poses: ``T_world_part`` is the part frame (its mesh frame), not PyBullet's
centre-of-mass frame; the conversion is done here. Units: metres, radians,
seconds, newtons.

Gripping (:mod:`~asmteach.core.arm.sim_gripper`) and camera images
(:mod:`~asmteach.core.arm.sim_camera`) act on such a world from their own modules.
"""

from __future__ import annotations

import logging
import os
import tempfile
from pathlib import Path

import numpy as np
import pybullet
from pybullet_utils import bullet_client

from asmteach.core import geometry
from asmteach.core.arm.insertion_records import PartContact
from asmteach.core.convex_pieces import decompose
from asmteach.core.errors import UserError
from asmteach.core.interfaces import PartModel

__all__ = ["CONE_FRICTION", "POSITION_GAIN", "PyBulletWorld", "pb_to_pose", "pose_to_pb"]

log = logging.getLogger(__name__)


CONTACT_MARGIN = 0.0
"""Collision margin of parts and table, metres. Bullet's default (about 1 mm per body) lifts parts off
the table and closes the 0.5 mm clearance of a peg in its hole; even 0.02 mm margins let a peg 0.3 mm off
its hole's axis jam on the rim, while exact convex pieces collide robustly without one."""


POSITION_GAIN = 1.0
"""``positionGain`` of the arm, chest and head joint servos (PyBullet's default is 0.1). PyBullet's position
control is a velocity motor aiming at ``gain * error / time_step``; with 0.1 the solver's residual under gravity
and a held part leaves a steady error of 0.3-1.3 mrad (0.2-0.4 mm at the TCP) however long the arm settles, and
such errors at the grasp of A and B and the release of A add up to more than a peg's 0.5 mm radial clearance in
its hole (demo seeds 16, 25, 28 jammed). With 1.0 the arm settles within 0.1 mrad (0.02 mm), as an industrial
position servo does."""


CONE_FRICTION = False
"""PyBullet's ``enableConeFriction``. Off: Bullet's pyramid friction, two tangent rows per contact each bounded by
``mu * normal force`` (so up to ``sqrt(2) * mu * N`` on the diagonal), instead of the implicit cone. The cone's rows
(an ``atan2`` and a ``sincos`` per contact per solver iteration) were half of the physics time of a demo trial: a
held part's contacts and the 65 convex pieces of the holed block resting on the table (about 180 contact points)
are solved at every one of the 240 steps a simulated second. Pyramid friction executes seed 1's plan in 9.8 s of
CPU instead of 15.5 s, the assembly ending within the run-to-run spread (docs/results/cycle_time.md, Session 14)."""

STALL_RAD_PER_STEP = 1e-6
"""A joint moving less than this per physics step (radians; 0.24 mrad/s at 240 Hz) is not moving."""
STALL_STEPS = 12
"""Settling stops after this many steps (0.05 s at 240 Hz) with no joint moving: the arm is held short of its goal."""


_EXACT_OBJ: dict[str, str] = {}
"""OBJ text of a parametric part's exact convex pieces, by part hash."""


def pose_to_pb(T: np.ndarray) -> tuple[list[float], list[float]]:
    """``(position, quaternion x y z w)`` lists, as PyBullet takes them, of a ``(4, 4)`` pose."""
    return T[:3, 3].tolist(), geometry.to_quat(T).tolist()


def pb_to_pose(pos: tuple[float, ...], orn: tuple[float, ...]) -> np.ndarray:
    """The ``(4, 4)`` pose of a PyBullet position and quaternion (x, y, z, w)."""
    return geometry.from_quat(orn, pos)


class PyBulletWorld:
    """The simulated robot and its world.

    Parameters
    ----------
    urdf : robot URDF; loaded with a fixed base at ``T_world_base``.
    gui : open PyBullet's window (needs a display; falls back to headless).
    time_step : physics step, seconds.
    position_gain : ``positionGain`` of the servos that hold and move the joints (see
        :data:`POSITION_GAIN`); :func:`~asmteach.core.arm.sim_gripper.grip` drives the fingers with PyBullet's default.
    """

    def __init__(
        self,
        urdf: Path,
        T_world_base: np.ndarray,
        *,
        gui: bool = False,
        time_step: float = 1.0 / 240.0,
        position_gain: float = POSITION_GAIN,
    ):
        mode = pybullet.DIRECT
        if gui:
            if os.environ.get("DISPLAY") or os.name == "nt":
                mode = pybullet.GUI
            else:
                log.warning("gui: true but no display; running PyBullet headless")
        self.p = bullet_client.BulletClient(connection_mode=mode)
        self.time_step = float(time_step)
        self.position_gain = float(position_gain)
        self.p.setTimeStep(self.time_step)
        self.p.setGravity(0.0, 0.0, -9.81)
        self.p.setPhysicsEngineParameter(enableConeFriction=int(CONE_FRICTION))
        self.T_world_base = np.asarray(T_world_base, dtype=float)
        pos, orn = pose_to_pb(self.T_world_base)
        flags = pybullet.URDF_USE_INERTIA_FROM_FILE
        try:
            self.robot = self.p.loadURDF(str(urdf), pos, orn, useFixedBase=True, flags=flags)
        except pybullet.error as exc:
            raise UserError(f"{urdf}: PyBullet cannot load it ({exc})") from None
        self.joint_index: dict[str, int] = {}
        self.link_index: dict[str, int] = {self.p.getBodyInfo(self.robot)[0].decode(): -1}
        for j in range(self.p.getNumJoints(self.robot)):
            info = self.p.getJointInfo(self.robot, j)
            self.joint_index[info[1].decode()] = j
            self.link_index[info[12].decode()] = j
        # Joints no plan moves (chest, head) would otherwise turn under the arms' reaction torques:
        # a 1 deg chest drift moves the hands ~9 mm away from where the kinematic model puts them.
        for j in self.joint_index.values():
            if self.p.getJointInfo(self.robot, j)[2] in (pybullet.JOINT_REVOLUTE, pybullet.JOINT_PRISMATIC):
                self.p.setJointMotorControl2(
                    self.robot,
                    j,
                    pybullet.POSITION_CONTROL,
                    targetPosition=self.p.getJointState(self.robot, j)[0],
                    force=1000.0,
                    positionGain=self.position_gain,
                )
        self.table_id: int | None = None
        self.parts: dict[str, tuple[int, PartModel]] = {}
        self.constraints: dict[str, tuple[int, str]] = {}  # arm -> (constraint id, part name)
        self.gears: dict[str, int] = {}  # arm -> gear constraint coupling its fingers
        self._tmp = tempfile.TemporaryDirectory(prefix="asmteach-pb-")
        self._shape_files: dict[str, str] = {}

    # ------------------------------------------------------------ robot state
    def joint_ids(self, names: list[str]) -> list[int]:
        try:
            return [self.joint_index[n] for n in names]
        except KeyError as exc:
            raise UserError(f"the simulated robot has no joint {exc.args[0]!r}") from None

    def set_joints(self, names: list[str], q: np.ndarray) -> None:
        """Teleport joints (no dynamics) and hold them there."""
        ids = self.joint_ids(names)
        for j, v in zip(ids, np.asarray(q, dtype=float), strict=True):
            self.p.resetJointState(self.robot, j, float(v), 0.0)
        self.p.setJointMotorControlArray(
            self.robot,
            ids,
            pybullet.POSITION_CONTROL,
            targetPositions=list(q),
            positionGains=[self.position_gain] * len(ids),
        )

    def get_joints(self, names: list[str]) -> np.ndarray:
        ids = self.joint_ids(names)
        return np.array([s[0] for s in self.p.getJointStates(self.robot, ids)])

    def link_pose(self, link: str) -> np.ndarray:
        """World pose of a URDF link frame (``computeForwardKinematics``)."""
        if link not in self.link_index:
            raise UserError(f"the simulated robot has no link {link!r}")
        idx = self.link_index[link]
        if idx < 0:
            return self.T_world_base.copy()  # the fixed base never moves
        st = self.p.getLinkState(self.robot, idx, computeForwardKinematics=True)
        return pb_to_pose(st[4], st[5])

    # ------------------------------------------------------------ world
    def reset_world(
        self,
        table_center: tuple[float, float],
        table_size: tuple[float, float],
        table_height: float,
        parts: dict[str, tuple[PartModel, np.ndarray]],
        thickness: float = 0.05,
    ) -> None:
        """Remove the old table, parts and grasps; add the table (top at ``table_height``) and the parts."""
        for cid, _ in self.constraints.values():
            self.p.removeConstraint(cid)
        self.constraints.clear()
        for body, _ in self.parts.values():
            self.p.removeBody(body)
        self.parts.clear()
        if self.table_id is not None:
            self.p.removeBody(self.table_id)
        half = [0.5 * table_size[0], 0.5 * table_size[1], 0.5 * thickness]
        col = self.p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
        vis = self.p.createVisualShape(pybullet.GEOM_BOX, halfExtents=half, rgbaColor=[0.55, 0.45, 0.35, 1.0])
        self.table_id = self.p.createMultiBody(
            0.0, col, vis, [table_center[0], table_center[1], table_height - 0.5 * thickness]
        )
        self.p.changeDynamics(self.table_id, -1, lateralFriction=0.8, collisionMargin=CONTACT_MARGIN)
        for name, (part, T) in parts.items():
            self.spawn_part(name, part, T)

    def _collision_shape(self, part: PartModel) -> int:
        # One convex decomposition for every part (asmteach.core.convex_pieces): exact pieces for parametric
        # solids and CAD meshes, CoACD only where an exact split would need too many pieces. V-HACD, used
        # here before, filled sub-millimetre clearances and grew faces by up to a millimetre.
        key = f"{part.source_hash or id(part.mesh)}_pieces"
        if key not in self._shape_files:
            # shared by every world of the process (plan re-checks make many); only content-hashed parts
            text = _EXACT_OBJ.get(part.source_hash) or decompose(part).obj()
            if part.source_hash:
                _EXACT_OBJ[part.source_hash] = text
            out = Path(self._tmp.name) / f"{key}.obj"
            out.write_text(text)
            self._shape_files[key] = str(out)
        # PyBullet makes one convex hull per object of an OBJ file: a compound of the pieces
        return self.p.createCollisionShape(pybullet.GEOM_MESH, fileName=self._shape_files[key])

    def spawn_part(self, name: str, part: PartModel, T_world_part: np.ndarray) -> int:
        """Add ``part`` at ``T_world_part`` (its mesh frame), with its mass and centre of mass."""
        T = geometry.as_transform(T_world_part)
        col = self._collision_shape(part)
        v = np.asarray(part.mesh.vertices)
        vis = self.p.createVisualShape(
            pybullet.GEOM_MESH,
            vertices=v.tolist(),
            indices=np.asarray(part.mesh.faces).reshape(-1).tolist(),
            rgbaColor=[*part.spec.color, 1.0],
        )
        pos, orn = pose_to_pb(T)
        body = self.p.createMultiBody(
            part.mass, col, vis, pos, orn, baseInertialFramePosition=np.asarray(part.center_of_mass).tolist()
        )
        self.p.changeDynamics(
            body,
            -1,
            lateralFriction=1.0,
            spinningFriction=0.002,
            rollingFriction=0.0005,
            collisionMargin=CONTACT_MARGIN,
        )
        self.parts[name] = (body, part)
        return body

    def part_pose(self, name: str) -> np.ndarray:
        """``T_world_part`` of a spawned part (mesh frame)."""
        if name not in self.parts:
            raise UserError(f"no part named {name!r} in the simulated world (have {sorted(self.parts)})")
        body, part = self.parts[name]
        pos, orn = self.p.getBasePositionAndOrientation(body)
        T_com = pb_to_pose(pos, orn)  # PyBullet reports the centre-of-mass frame
        T_part_com = np.eye(4)
        T_part_com[:3, 3] = part.center_of_mass
        return T_com @ np.linalg.inv(T_part_com)

    def part_contact(self, part: str, other: str) -> PartContact:
        """The contact between two spawned parts now: total normal force (N), its force-weighted point on
        ``part``, ``part``'s centre of mass (world, metres), the total force on ``part`` (world, N) and its moment
        about the world origin (N m): the wrench a wrist F/T sensor reads when the hand holds ``part``. Normal
        forces only: PyBullet's friction directions do not say on which of the two bodies they act."""
        for name in (part, other):
            if name not in self.parts:
                raise UserError(f"no part named {name!r} in the simulated world (have {sorted(self.parts)})")
        body, other_body = self.parts[part][0], self.parts[other][0]
        com = np.asarray(self.p.getBasePositionAndOrientation(body)[0], dtype=float)
        points = self.p.getContactPoints(body, other_body)
        force = float(sum(c[9] for c in points))
        if force <= 1e-9:
            return PartContact(force, None, com)
        where = sum(c[9] * np.asarray(c[5], dtype=float) for c in points) / force
        # contactNormalOnB points from the other part to ``part``: each normal force pushes ``part`` along it
        push = sum(c[9] * np.asarray(c[7], dtype=float) for c in points)
        moment = sum(c[9] * np.cross(c[5], c[7]) for c in points)
        return PartContact(force, where, com, np.asarray(push, dtype=float), np.asarray(moment, dtype=float))

    # ------------------------------------------------------------ motion
    def step(self, n: int = 1) -> None:
        for _ in range(n):
            self.p.stepSimulation()

    def track(
        self,
        names: list[str],
        times: np.ndarray,
        positions: np.ndarray,
        speed: np.ndarray,
        forces: np.ndarray,
        settle: float = 1.0,
        tol: float = 1e-4,
    ) -> np.ndarray:
        """Follow a time-parametrised path with position control, capped at ``speed`` (rad/s).

        The path is sampled at every physics step (linear between waypoints);
        after its end the controller gets up to ``settle`` seconds to reach the
        last waypoint within ``tol`` radians. Returns the final joint positions.
        """
        ids = self.joint_ids(names)
        t_end = float(times[-1] - times[0])
        n_steps = max(1, int(np.ceil(t_end / self.time_step)))
        # Every step's targets at once (np.interp is elementwise, so the values are those of one call per step
        # and joint), and the client's methods bound once: BulletClient builds a new partial per attribute
        # access; 240 steps per simulated second times up to 15 joints made that Python work add up.
        t_all = times[0] + np.minimum(np.arange(1, n_steps + 1) * self.time_step, t_end)
        targets = np.column_stack([np.interp(t_all, times, positions[:, i]) for i in range(len(ids))]).tolist()
        motor, step = self.p.setJointMotorControl2, self.p.stepSimulation
        robot, mode = self.robot, pybullet.POSITION_CONTROL
        limits = [(j, float(forces[i]), float(speed[i])) for i, j in enumerate(ids)]
        gain = self.position_gain
        for target in targets:
            for (j, f, v), x in zip(limits, target, strict=True):
                motor(robot, j, mode, targetPosition=x, force=f, maxVelocity=v, positionGain=gain)
            step()
        goal = positions[-1]
        # Settle until the joints reach the goal, or until they have stalled short of it: an arm pressing a part
        # against resistance (a guarded insertion's probe) never reaches ``tol``, and waiting the whole ``settle``
        # there cost a second of simulation per probe. Free of contact, the servo closes a share of the error per
        # step, far above the stall threshold until the error is well under ``tol``.
        q_prev, still = self.get_joints(names), 0
        for _ in range(int(settle / self.time_step)):
            if np.max(np.abs(q_prev - goal)) < tol:
                break
            step()
            q = self.get_joints(names)
            still = still + 1 if np.max(np.abs(q - q_prev)) < STALL_RAD_PER_STEP else 0
            q_prev = q
            if still >= STALL_STEPS:
                break
        return q_prev

    def close(self) -> None:
        try:
            self.p.disconnect()
        except pybullet.error:
            pass
        self._tmp.cleanup()
