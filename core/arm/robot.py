"""An arm robot on pinocchio kinematics, fcl collision and a PyBullet world: a :class:`Robot` and a :class:`World`.

The base of the robot plugins that load a URDF (the Nextage, ``urdf_arm``); a
subclass only says where its URDF, arms, gripper and home are. The simulator
starts lazily (the first :meth:`reset_world`), so planners that only need
kinematics and collision checking never pay for PyBullet.

Planning and the world are kept apart: :attr:`ArmRobot.scene` is an
:class:`~asmteach.core.arm.scene.ArmScene` value, and changing it (or querying
another scene) never moves the simulator; :meth:`execute`, :meth:`grip` and
:meth:`reset_world` move the world and then set :attr:`scene` to match it.

Frames: world, z up, metres; ``T_world_tcp`` follows :class:`HandSpec` (z =
approach out of the palm, y = jaw axis).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import trimesh

from asmteach.core.arm.batch_ik import ik_many
from asmteach.core.arm.collision import CollisionChecker
from asmteach.core.arm.insertion_records import PartContact
from asmteach.core.arm.kinematics import Kinematics
from asmteach.core.arm.plan_check import CheckedArm, PlanCheck
from asmteach.core.arm.plan_checker import recheck_plan
from asmteach.core.arm.scene import ArmScene, SceneBinding
from asmteach.core.arm.settings import ArmRobotSettings
from asmteach.core.arm.sim import PyBulletWorld
from asmteach.core.arm.sim_camera import render_rgb, wrist_camera_of
from asmteach.core.arm.sim_gripper import GripperJoints, grip
from asmteach.core.errors import UserError
from asmteach.core.interfaces import IKResult, Obstacle, PartModel, Robot
from asmteach.core.models import HandSpec, Plan, StrictModel, TablePlane, Trajectory
from asmteach.core.robot import World, WristCamera

__all__ = ["ArmRobot", "ArmSpec"]


@dataclass
class ArmSpec:
    """One arm as the subclass describes it."""

    joints: list[str]
    tcp_link: str
    home: np.ndarray
    gripper: GripperJoints
    hand_links: list[str]


class ArmRobot(Robot, World):
    """A robot with named arms, a parallel gripper per arm and a simulated world."""

    Settings = ArmRobotSettings
    settings: ArmRobotSettings

    def __init__(self, settings: StrictModel | dict | None = None, *, seed: int = 0) -> None:
        super().__init__(settings, seed=seed)
        self._ik_rng = self.rng(7)
        self._sim: PyBulletWorld | None = None
        self._table = TablePlane(height=self.settings.table_height)
        self._world_q: dict[str, np.ndarray] = {}  # arm -> joints in the world (radians)
        self._depth_cams: list[Any] = []  # the virtual Kinects, made on the first sense_depth (open3d loads then)
        self._wrist: dict[str, tuple[WristCamera, Any, np.random.Generator]] = {}  # arm -> camera, model, noise

    def _setup(
        self,
        urdf,
        T_world_base: np.ndarray,
        arms: dict[str, ArmSpec],
        hand: HandSpec,
        disabled: Sequence[tuple[str, str]],
    ) -> None:
        """Called by subclasses once they know their robot."""
        self.urdf = urdf
        self.T_world_base = np.asarray(T_world_base, dtype=float)
        self._arms = arms
        self._hand = hand
        self.kin = Kinematics(
            urdf,
            {a: (s.joints, s.tcp_link) for a, s in arms.items()},
            self.T_world_base,
            self.settings.ik,
            homes={a: s.home for a, s in arms.items()},
        )
        self.checker = CollisionChecker(
            self.kin, disabled=disabled, hand_links={a: s.hand_links for a, s in arms.items()}
        )
        st = self.settings
        self.checker.set_table(st.table_center, st.table_size, st.table_height)
        self._binding = SceneBinding(self.kin, self.checker, {a: s.gripper for a, s in arms.items()})
        for a, s in arms.items():  # the kinematic state at home, hands open: the state subclasses inspect
            self.kin.set_arm(a, s.home)
            self._set_fingers(a, s.gripper.open_values)
        self._world_q = {a: s.home.copy() for a, s in arms.items()}
        self.scene = ArmScene(self._binding, self._world_q, table=self._table_obstacle(st.table_height))
        unknown = sorted(set(st.wrist_camera.arms) - set(arms)) if st.wrist_camera is not None else []
        if unknown:
            raise UserError(f"robot.settings.wrist_camera.arms: no arm {unknown}; this robot has {list(arms)}")

    def _table_obstacle(self, height: float, thickness: float = 0.05) -> Obstacle:
        """The table as the checker models it: a ``thickness`` slab whose top face is at ``height`` (metres)."""
        st = self.settings
        T = np.eye(4)
        T[:3, 3] = [st.table_center[0], st.table_center[1], height - 0.5 * thickness]
        return Obstacle("table", trimesh.creation.box(extents=[st.table_size[0], st.table_size[1], thickness]), T)

    def _set_fingers(self, arm: str, values: Sequence[float]) -> None:
        self._binding.set_fingers(arm, values)

    # ------------------------------------------------------------ description
    @property
    def arms(self) -> list[str]:
        return list(self._arms)

    @property
    def hand(self) -> HandSpec:
        return self._hand

    def _arm(self, arm: str) -> ArmSpec:
        if arm not in self._arms:
            raise UserError(f"unknown arm {arm!r}; this robot has {self.arms}")
        return self._arms[arm]

    def joint_names(self, arm: str) -> list[str]:
        return list(self._arm(arm).joints)

    def joint_limits(self, arm: str) -> tuple[np.ndarray, np.ndarray]:
        c = self.kin.chain(arm)
        return c.lower.copy(), c.upper.copy()

    def speed_limits(self, arm: str) -> np.ndarray:
        """Joint speed limits (rad/s) used by :meth:`execute`, after ``speed_scale``."""
        return self.kin.chain(arm).velocity * self.settings.speed_scale

    def home(self, arm: str) -> np.ndarray:
        return self._arm(arm).home.copy()

    def current(self, arm: str) -> np.ndarray:
        """The arm's joints in the world (where the last trajectory ended; home after a reset), radians."""
        self._arm(arm)
        return self._world_q[arm].copy()

    def set_configuration(self, arm: str, q: np.ndarray) -> None:
        """:attr:`scene` with the arm at ``q`` (checked against the limits); the simulator stays where it is."""
        self.scene = self.scene.with_configuration(arm, self.kin.check_limits(arm, q))

    # ------------------------------------------------------------ kinematics
    def fk(self, arm: str, q: np.ndarray) -> np.ndarray:
        return self.kin.fk(arm, q)

    def jacobian(self, arm: str, q: np.ndarray) -> np.ndarray:
        """``(6, dof)`` TCP Jacobian (linear; angular) in world axes."""
        return self.kin.jacobian(arm, q)

    def ik(self, arm: str, T_world_tcp: np.ndarray, q_seed: np.ndarray | None = None) -> IKResult:
        if arm not in self._arms:
            return IKResult(False, None, reason=f"unknown arm {arm!r}; this robot has {self.arms}")
        return self.kin.ik(arm, T_world_tcp, q_seed if q_seed is not None else self.current(arm), rng=self._ik_rng)

    def ik_many(self, arm: str, T_world_tcp: np.ndarray, q_seed: np.ndarray | None = None) -> list[IKResult]:
        if arm not in self._arms:
            return [
                IKResult(False, None, reason=f"unknown arm {arm!r}; this robot has {self.arms}")
                for _ in np.asarray(T_world_tcp).reshape(-1, 4, 4)
            ]
        return ik_many(
            self.kin, arm, T_world_tcp, q_seed if q_seed is not None else self.current(arm), rng=self._ik_rng
        )

    # ------------------------------------------------------------ simulation
    @property
    def sim(self) -> PyBulletWorld:
        """The PyBullet world (started on first use)."""
        if self._sim is None:
            self._sim = PyBulletWorld(
                self.urdf,
                self.T_world_base,
                gui=self.settings.gui,
                time_step=self.settings.time_step,
                position_gain=self.settings.position_gain,
            )
            for a, s in self._arms.items():
                self._sim.set_joints(s.joints, self.kin.get_arm(a))
                self._sim.set_joints(s.gripper.finger_joints, s.gripper.open_values)
        return self._sim

    def reset_world(self, table: TablePlane, parts: dict[str, tuple[PartModel, np.ndarray]]) -> None:
        """Fresh world: the table (top at ``table.height``, extent from the settings), the parts, arms at home."""
        st = self.settings
        self._table = table
        self.checker.set_table(st.table_center, st.table_size, table.height)
        self._binding.invalidate()
        self._world_q = {a: s.home.copy() for a, s in self._arms.items()}
        self.scene = ArmScene(self._binding, self._world_q, table=self._table_obstacle(table.height))
        self.sim.reset_world(st.table_center, st.table_size, table.height, parts)
        for s in self._arms.values():
            self.sim.set_joints(s.joints, s.home)
            self.sim.set_joints(s.gripper.finger_joints, s.gripper.open_values)

    def check_trajectory(self, trajectory: Trajectory) -> tuple[np.ndarray, np.ndarray]:
        """``(times, positions)`` of a valid trajectory, or :class:`UserError` saying what is wrong."""
        arm = trajectory.arm
        names = self.joint_names(arm)
        if list(trajectory.joint_names) != names:
            raise UserError(f"trajectory for arm {arm!r} names joints {trajectory.joint_names}; expected {names}")
        times = np.asarray(trajectory.times, dtype=float)
        pos = np.atleast_2d(np.asarray(trajectory.positions, dtype=float))
        if len(times) == 0:
            raise UserError(f"trajectory for arm {arm!r} is empty")
        self.kin.check_limits(arm, pos)
        start_gap = np.abs(pos[0] - self.current(arm))
        if np.max(start_gap) > self.settings.start_tolerance:
            k = int(np.argmax(start_gap))
            raise UserError(
                f"trajectory for arm {arm!r} starts {start_gap[k]:.3f} rad away from the current "
                f"{names[k]}; start it at the current configuration"
            )
        if len(times) > 1:
            dt = np.diff(times)
            dq = np.abs(np.diff(pos, axis=0))
            limit = self.kin.chain(arm).velocity * self.settings.jump_tolerance
            need = dq / limit[None]  # seconds each joint needs for each segment
            bad = need > dt[:, None] + 1e-9
            if np.any(bad):
                i, k = (int(v) for v in np.argwhere(bad)[0])
                raise UserError(
                    f"trajectory for arm {arm!r} jumps: {names[k]} moves {dq[i, k]:.3f} rad in "
                    f"{dt[i]:.3f} s between waypoints {i} and {i + 1} (limit {limit[k]:.2f} rad/s); "
                    "re-time it or add waypoints"
                )
        return times, pos

    def execute(self, trajectory: Trajectory) -> None:
        """Run the trajectory with position control under the joint speed limits; the arm ends at its last point."""
        times, pos = self.check_trajectory(trajectory)
        arm = trajectory.arm
        names = self.joint_names(arm)
        sim = self.sim
        if len(times) == 1:
            times, pos = np.array([0.0, 0.0]), np.vstack([pos, pos])
        ids = sim.joint_ids(names)
        forces = np.array([max(sim.p.getJointInfo(sim.robot, j)[10], 1.0) for j in ids]) * 2.0
        final = np.clip(sim.track(names, times, pos, self.speed_limits(arm), forces), *self.joint_limits(arm))
        self._world_q[arm] = final
        self.scene = self.scene.with_configuration(arm, final)

    def grip(self, arm: str, close: bool, part: str | None = None) -> bool:
        """Close to contact and weld ``part`` to the TCP (True when held), or open and release."""
        g = self._arm(arm).gripper
        s = self.sim
        speed = max(abs(s.p.getJointInfo(s.robot, s.joint_index[g.finger_joints[0]])[11]), 0.05)
        held = grip(s, arm, g, close, part, self.settings.grip_force, speed)
        if held and part is not None:
            T_tcp_part = np.linalg.solve(self.fk(arm, self.current(arm)), s.part_pose(part))
            # the jaw as wide as the fingers stand now (each finger joint is half the opening)
            width = float(np.sum(np.abs(s.get_joints(g.finger_joints))))
            self.scene = self.scene.with_attached(arm, s.parts[part][1], T_tcp_part, width=width)
        elif not close:
            self.scene = self.scene.with_attached(arm, None)
        return held

    def verify_plan(
        self, plan: Plan, parts: dict[str, tuple[PartModel, np.ndarray]], table: TablePlane, resolution: float = 0.005
    ) -> PlanCheck:
        """Re-check ``plan`` independently of the planner's collision model, in PyBullet.

        Replays the plan kinematically in a separate PyBullet DIRECT client built from this
        robot's URDF, base pose and table settings (extent from the settings, top at
        ``table.height``), with the arms starting at :meth:`home` and ``parts`` (name -> model and
        start pose ``T_world_part``, metres) spawned as for execution. Every trajectory is
        checked so densely that no point of the robot or of a held part moves more than
        ``resolution`` metres between checks. A collision is a penetration deeper than 0.5 mm
        between any robot link and the table or a part, a held part and the table or another
        part, or two robot links (except links joined by a joint and the pairs this robot never
        checks); allowed are the holding hand touching its part and the held part touching the
        table on close/lift/place/insert and the other part on close/insert
        (:data:`~asmteach.core.arm.plan_check.TOUCH_RULES`). The simulator this
        robot executes in is not touched.

        Returns a :class:`~asmteach.core.arm.plan_check.PlanCheck`: ``ok``, the
        configurations checked, the least signed distance (metres) and every colliding pair with
        its segment index, label, time (s from the segment's start) and penetration (metres).
        """
        arms = {
            a: CheckedArm(
                tuple(s.joints),
                s.tcp_link,
                tuple(s.gripper.finger_joints),
                tuple(s.gripper.open_values),
                tuple(s.hand_links),
            )
            for a, s in self._arms.items()
        }
        st = self.settings
        return recheck_plan(
            self.urdf,
            self.T_world_base,
            plan,
            parts,
            arms,
            {a: self.home(a) for a in self.arms},
            table_center=st.table_center,
            table_size=st.table_size,
            table_height=table.height,
            skip_pairs=self.checker.disabled,
            resolution=resolution,
        )

    def part_pose(self, name: str) -> np.ndarray:
        return self.sim.part_pose(name)

    def part_contact(self, part: str, other: str) -> PartContact:
        """The contact between two parts now (:meth:`~asmteach.core.arm.sim.PyBulletWorld.part_contact`: the
        normal forces' total, point, push and moment); what :func:`~asmteach.core.arm.insertion.guarded_insert`
        reads (:class:`~asmteach.core.arm.insertion_records.ContactSensing`)."""
        return self.sim.part_contact(part, other)

    def camera_pose(self, view: int = 0) -> np.ndarray:
        """``T_world_cam`` (OpenCV frame) of depth camera ``view`` (0: the one the RGB camera shares)."""
        from asmteach.core.perception.depth_camera import look_at

        c, h = self._mount(view), self._table.height
        return look_at([c.eye[0], c.eye[1], h + c.eye[2]], [c.target[0], c.target[1], h + c.target[2]])

    def depth_views(self) -> int:
        """How many depth cameras the cell has (``settings.camera``, and ``settings.second_camera`` if set)."""
        return 1 if self.settings.second_camera is None else 2

    def _mount(self, view: int) -> Any:
        if view == 0:
            return self.settings.camera
        if view == 1 and self.settings.second_camera is not None:
            return self.settings.second_camera
        raise UserError(f"depth camera {view} is not configured (the robot has {self.depth_views()})")

    def _scene_meshes(self) -> list[tuple[trimesh.Trimesh, np.ndarray]]:
        """Table, parts and the robot's collision primitives at their current world poses."""
        world = self.scene
        for a, q in self._world_q.items():
            world = world.with_configuration(a, q)
        self._binding.checker_at(world, self.arms[0])  # the kinematic state at the world's joints
        st = self.settings
        table = trimesh.creation.box(extents=[st.table_size[0], st.table_size[1], 0.05])
        T_table = np.eye(4)
        T_table[:3, 3] = [st.table_center[0], st.table_center[1], self._table.height - 0.025]
        meshes = [(table, T_table)]
        for name, (_, part) in self.sim.parts.items():
            meshes.append((part.mesh, self.sim.part_pose(name)))
        _, static = self.kin.batch_joint_poses(self.arms[0], self.current(self.arms[0])[None])
        for g in self.checker.robot:
            if g.kind == "box":
                mesh = trimesh.creation.box(extents=2.0 * g.half)
            elif g.kind == "cylinder":
                mesh = trimesh.creation.cylinder(radius=g.half[0], height=2.0 * g.half[2], sections=24)
            elif g.kind == "mesh" and g.mesh is not None:  # a vendor's link mesh is in its geometry frame
                meshes.append((g.mesh, static[g.joint] @ g.placement))
                continue
            else:
                continue
            meshes.append((mesh, static[g.joint] @ g.placement @ g.obb))
        return meshes

    def sense_depth(self, view: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Kinect-v1 depth ``(480, 640)`` metres (NaN = no return) and the world-frame cloud ``(n, 3)``
        of the table and the parts (points on the robot itself are filtered out), from depth camera ``view``.

        Uses the project's one depth-camera model
        (:mod:`asmteach.core.perception.depth_camera`) at :meth:`camera_pose`. Each camera draws its
        noise from its own generator, so the first camera's frames do not change when a second is added.
        """
        from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings

        pose = self.camera_pose(view)
        while len(self._depth_cams) <= view:
            # camera 0 keeps the seed it always had: the first view is the same with or without a second
            k = len(self._depth_cams)
            self._depth_cams.append(DepthCamera(KinectSettings(), seed=self.seed if k == 0 else 1000 * k + self.seed))
        meshes = self._scene_meshes()
        frame = self._depth_cams[view].render(meshes, pose)
        # Robot self-filter (as robot_self_filter does on a real cell): the cloud keeps the table and
        # the parts; the depth image keeps everything the sensor saw.
        n_world = 1 + len(self.sim.parts)
        return frame.depth, frame.points_world[frame.labels < n_world]

    def wrist_cameras(self) -> list[str]:
        """The arms of ``settings.wrist_camera.arms`` (none when it is null), in :attr:`arms` order."""
        mount = self.settings.wrist_camera
        return [] if mount is None else [a for a in self.arms if a in mount.arms]

    def wrist_camera(self, arm: str) -> WristCamera:
        """``arm``'s wrist camera: ``T_tcp_cam`` (TCP frame, metres) and its sensor (``settings.wrist_camera``)."""
        return self._wrist_parts(arm)[0]

    def _wrist_parts(self, arm: str) -> tuple[WristCamera, Any, np.random.Generator]:
        if arm not in self._wrist:
            if arm not in self.wrist_cameras():
                raise UserError(f"arm {arm!r} has no wrist camera (the arms with one: {self.wrist_cameras()})")
            from asmteach.core.perception.depth_camera import DepthCamera

            cam = wrist_camera_of(self.settings.wrist_camera)
            # its own noise, seeded from the run seed and the arm: the fixed cameras' frames do not change
            rng = self.rng(2000, self.arms.index(arm))
            self._wrist[arm] = (cam, DepthCamera(cam.sensor), rng)
        return self._wrist[arm]

    def sense_wrist(self, arm: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``arm``'s wrist camera at the arm's joints now: depth ``(h, w)`` metres (NaN = no return), the
        world-frame cloud ``(n, 3)`` of the table and the parts (the robot self-filtered as in
        :meth:`sense_depth`) and ``T_world_cam = fk(arm, current(arm)) @ T_tcp_cam`` ``(4, 4)``."""
        cam, model, rng = self._wrist_parts(arm)
        pose = self.fk(arm, self.current(arm)) @ cam.T_tcp_cam
        frame = model.render(self._scene_meshes(), pose, rng=rng)
        n_world = 1 + len(self.sim.parts)
        return frame.depth, frame.points_world[frame.labels < n_world], pose

    def sense_rgb(self) -> np.ndarray:
        """RGB image ``(480, 640, 3) uint8`` from the same camera pose (PyBullet TinyRenderer)."""
        from asmteach.core.perception.depth_camera import KinectSettings

        k = KinectSettings()
        return render_rgb(self.sim.p, self.camera_pose(), k.width, k.height, k.fx, k.fy, k.cx, k.cy)

    def close(self) -> None:
        if self._sim is not None:
            self._sim.close()
            self._sim = None
