"""A gantry robot with a spherical wrist, written as a third party would: on asmteach's core contracts only.

Kinematics (:class:`~asmteach.core.robot.RobotModel`): one arm ``"main"``,
``q = (x, y, z, a, b, c)``: three prismatic axes (metres, world frame) carry
a ZYZ wrist (radians), ``T_world_tcp = Trans(x, y, z) Rz(a) Ry(b) Rz(c) Rx(pi)``,
so ``q = (x, y, z, 0, 0, 0)`` points the hand straight down. IK is closed form.

World (:class:`~asmteach.core.robot.World`): kinematic, no physics. A closed
hand holds a part when the TCP is within half the stroke of its surface; a
held part moves rigidly with the TCP; an opened hand leaves the part where it
is. Depth comes from asmteach's one virtual Kinect
(:mod:`asmteach.core.perception.depth_camera`) seeing the table and the
parts; there is no colour camera (:meth:`World.sense_rgb` is not offered).

Frames: world, z up, metres, radians; the table top at ``table_height``.
"""

from __future__ import annotations

import numpy as np
import trimesh
from pydantic import Field
from scipy.spatial.transform import Rotation

from asmteach.core.errors import UserError
from asmteach.core.interfaces import IKResult, PartModel, Robot
from asmteach.core.models import HandSpec, StrictModel, TablePlane, Trajectory
from asmteach.core.robot import World
from asmteach_gantry.scene import GantryScene, TableBox

__all__ = ["GantryRobot", "GantrySettings"]

_DOWN = np.diag([1.0, -1.0, -1.0])  # Rx(pi): TCP z (approach) along world -z


class GantrySettings(StrictModel):
    """The gantry's workspace and table (metres, radians, seconds)."""

    table_center: tuple[float, float] = Field((0.45, 0.0), description="table centre x, y (world)")
    table_size: tuple[float, float] = Field((0.6, 1.2), description="table extent along x, y")
    table_height: float = Field(0.0, description="world z of the table top")
    reach_above_table: float = Field(0.6, gt=0.0, description="highest TCP z above the table top")
    linear_speed: float = Field(0.5, gt=0.0, description="m/s on each prismatic axis")
    wrist_speed: float = Field(2.0, gt=0.0, description="rad/s on each wrist joint")
    camera_eye: tuple[float, float, float] = Field((1.05, 0.0, 0.75), description="z above the table top")
    camera_target: tuple[float, float, float] = Field((0.45, 0.0, 0.0), description="z above the table top")


def _hand() -> HandSpec:
    return HandSpec(
        name="gantry_hand",
        max_width=0.08,
        finger_size=[0.012, 0.02, 0.05],
        pad_size=(0.02, 0.018),
        palm_center=[0.0, 0.0, -0.075],
        palm_size=[0.06, 0.2, 0.06],
        max_force=60.0,
    )


class GantryRobot(Robot, World):
    """A 3-axis gantry with a ZYZ wrist and a parallel gripper, in a kinematic world."""

    Settings = GantrySettings
    settings: GantrySettings
    ARM = "main"

    def __init__(self, settings: GantrySettings | dict | None = None, *, seed: int = 0) -> None:
        super().__init__(settings, seed=seed)
        st = self.settings
        h = st.table_height
        cx, cy = st.table_center
        sx, sy = st.table_size
        self._lower = np.array([cx - 0.5 * sx - 0.1, cy - 0.5 * sy - 0.1, h, -2 * np.pi, -np.pi, -2 * np.pi])
        self._upper = np.array(
            [cx + 0.5 * sx + 0.1, cy + 0.5 * sy + 0.1, h + st.reach_above_table, 2 * np.pi, np.pi, 2 * np.pi]
        )
        self._home = np.array([cx - 0.5 * sx + 0.05, 0.0, h + 0.3, 0.0, 0.0, 0.0])
        self._hand = _hand()
        self._camera = None
        self._reset_state(TablePlane(height=h), {})

    def _reset_state(self, table: TablePlane, parts: dict[str, tuple[PartModel, np.ndarray]]) -> None:
        st = self.settings
        self._table = TableBox(tuple(st.table_center), tuple(st.table_size), float(table.height))
        self._q = self._home.copy()
        self._parts = {name: (model, np.asarray(T, float).copy()) for name, (model, T) in parts.items()}
        self._held: dict[str, tuple[str, np.ndarray]] = {}  # arm -> (part, T_tcp_part)
        self.scene = GantryScene(self.fk, self._hand, self._table, {self.ARM: self._q})

    # ------------------------------------------------------------ RobotModel
    @property
    def arms(self) -> list[str]:
        return [self.ARM]

    @property
    def hand(self) -> HandSpec:
        return self._hand

    def _check_arm(self, arm: str) -> None:
        if arm != self.ARM:
            raise UserError(f"unknown arm {arm!r}; the gantry has ['main']")

    def joint_names(self, arm: str) -> list[str]:
        self._check_arm(arm)
        return ["x", "y", "z", "wrist_a", "wrist_b", "wrist_c"]

    def joint_limits(self, arm: str) -> tuple[np.ndarray, np.ndarray]:
        self._check_arm(arm)
        return self._lower.copy(), self._upper.copy()

    def home(self, arm: str) -> np.ndarray:
        self._check_arm(arm)
        return self._home.copy()

    def speed_limits(self, arm: str) -> np.ndarray:
        st = self.settings
        return np.array([st.linear_speed] * 3 + [st.wrist_speed] * 3)

    def fk(self, arm: str, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, float)
        T = np.eye(4)
        T[:3, :3] = Rotation.from_euler("ZYZ", q[3:6]).as_matrix() @ _DOWN
        T[:3, 3] = q[:3]
        return T

    def ik(self, arm: str, T_world_tcp: np.ndarray, q_seed: np.ndarray | None = None) -> IKResult:
        if arm != self.ARM:
            return IKResult(False, None, reason=f"unknown arm {arm!r}; the gantry has ['main']")
        T = np.asarray(T_world_tcp, float)
        seed = self._q if q_seed is None else np.asarray(q_seed, float)
        wrist = T[:3, :3] @ _DOWN.T
        b = float(np.arccos(np.clip(wrist[2, 2], -1.0, 1.0)))
        if np.sin(b) < 1e-7:  # straight down or up: only a + c (or a - c) is fixed; keep the seed's a
            a = float(seed[3])
            c = (
                float(np.arctan2(wrist[1, 0], wrist[0, 0])) - a
                if np.cos(b) > 0
                else a - float(np.arctan2(-wrist[1, 0], -wrist[0, 0]))
            )
            candidates = [(a, b, c)]
        else:
            a = float(np.arctan2(wrist[1, 2], wrist[0, 2]))
            c = float(np.arctan2(wrist[2, 1], -wrist[2, 0]))
            candidates = [(a, b, c), (a + np.pi, -b, c + np.pi)]
        best = None
        for abc in candidates:
            q = np.concatenate([T[:3, 3], [_near(v, s) for v, s in zip(abc, seed[3:], strict=True)]])
            if np.all(q >= self._lower - 1e-9) and np.all(q <= self._upper + 1e-9):
                if best is None or np.linalg.norm(q[3:] - seed[3:]) < np.linalg.norm(best[3:] - seed[3:]):
                    best = q
        if best is None:
            return IKResult(False, None, reason="TCP position outside the gantry's travel")
        err = self.fk(arm, best)
        pos = float(np.linalg.norm(err[:3, 3] - T[:3, 3]))
        rot = float(Rotation.from_matrix(err[:3, :3].T @ T[:3, :3]).magnitude())
        return IKResult(pos < 1e-6 and rot < 1e-6, best, pos, rot, reason=None if rot < 1e-6 else "wrist")

    # ------------------------------------------------------------ World
    def reset_world(self, table: TablePlane, parts: dict[str, tuple[PartModel, np.ndarray]]) -> None:
        self._reset_state(table, parts)

    def current(self, arm: str) -> np.ndarray:
        self._check_arm(arm)
        return self._q.copy()

    def execute(self, trajectory: Trajectory) -> None:
        self._check_arm(trajectory.arm)
        if list(trajectory.joint_names) != self.joint_names(trajectory.arm):
            raise UserError(
                f"trajectory names joints {trajectory.joint_names}; the gantry's are {self.joint_names(trajectory.arm)}"
            )
        pos = np.atleast_2d(np.asarray(trajectory.positions, float))
        if np.max(np.abs(pos[0] - self._q)) > 1e-3:
            raise UserError("trajectory does not start at the gantry's current configuration")
        if np.any(pos < self._lower - 1e-6) or np.any(pos > self._upper + 1e-6):
            raise UserError("trajectory leaves the gantry's joint limits")
        self._q = np.clip(pos[-1], self._lower, self._upper)
        self.scene = self.scene.with_configuration(self.ARM, self._q)

    def grip(self, arm: str, close: bool, part: str | None = None) -> bool:
        self._check_arm(arm)
        if not close:
            self._held.pop(arm, None)
            self.scene = self.scene.with_attached(arm, None)
            return False
        if part is None or part not in self._parts:
            return False
        model, T_part = self._parts[part][0], self.part_pose(part)
        T_tcp = self.fk(arm, self._q)
        local = np.linalg.solve(T_part, np.append(T_tcp[:3, 3], 1.0))[:3]
        _, distance, _ = trimesh.proximity.closest_point(model.mesh, local[None])
        if float(distance[0]) > 0.5 * self._hand.max_width:
            return False
        T_tcp_part = np.linalg.solve(T_tcp, T_part)
        self._held[arm] = (part, T_tcp_part)
        self.scene = self.scene.with_attached(arm, model, T_tcp_part, width=None)
        return True

    def part_pose(self, name: str) -> np.ndarray:
        if name not in self._parts:
            raise UserError(f"no part named {name!r} in the gantry's world")
        for arm, (held, T_tcp_part) in self._held.items():
            if held == name:
                T = self.fk(arm, self._q) @ T_tcp_part
                self._parts[name] = (self._parts[name][0], T)  # where it stays when released
                return T.copy()
        return self._parts[name][1].copy()

    def camera_pose(self) -> np.ndarray:
        from asmteach.core.perception.depth_camera import look_at

        st, h = self.settings, self._table.height
        e, t = st.camera_eye, st.camera_target
        return look_at([e[0], e[1], h + e[2]], [t[0], t[1], h + t[2]])

    def sense_depth(self) -> tuple[np.ndarray, np.ndarray]:
        from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings

        if self._camera is None:
            self._camera = DepthCamera(KinectSettings(), seed=self.seed)
        tb = self._table
        slab = trimesh.creation.box(extents=[tb.size[0], tb.size[1], 0.05])
        T_slab = np.eye(4)
        T_slab[:3, 3] = [tb.center[0], tb.center[1], tb.height - 0.025]
        meshes = [(slab, T_slab)] + [(model.mesh, self.part_pose(name)) for name, (model, _) in self._parts.items()]
        frame = self._camera.render(meshes, self.camera_pose())
        return frame.depth, frame.points_world


def _near(angle: float, seed: float) -> float:
    """``angle`` plus the multiple of 2 pi that brings it nearest ``seed`` (radians)."""
    return float(angle + 2.0 * np.pi * np.round((seed - angle) / (2.0 * np.pi)))
