"""The robot as three contracts: what a caller may ask of it, split by who asks.

- :class:`RobotModel`: stateless kinematics (arms, joints and limits, FK, IK,
  the hand, speed and acceleration limits). Grasp and assembly planners use it.
- :class:`PlanningScene`: an immutable value (every arm's configuration, the
  obstacles, the parts attached to the hands) that answers collision and
  clearance queries. A planner receives one and makes new ones with
  :meth:`~PlanningScene.with_configuration`, :meth:`~PlanningScene.with_obstacles`
  and :meth:`~PlanningScene.with_attached`; it never changes one in place, so
  planning cannot move the world.
- :class:`World`: the cell itself, simulated or real (reset, execute a
  trajectory, grip, sense depth and RGB, the camera pose, the parts' true
  poses; optionally a depth camera on a hand, :class:`WristCamera`). Only the
  pipeline holds it.

The config's ``robot:`` section builds one :class:`~asmteach.core.interfaces.Robot`,
which is a :class:`RobotModel` carrying its current :class:`PlanningScene`; a
robot the pipeline can run is also a :class:`World`.

A planner works on scene values and hands back the one it ends with::

    scene = robot.scene.with_obstacles(others)           # the world as planning starts
    free = ~scene.in_collision(arm, path)                # (n,) bool for an (n, dof) path
    carrying = scene.with_attached(arm, part, T_tcp_part, width=grasp.width)
    waiting = carrying.with_configuration(other_arm, q_other)   # the other arm parked there

Frames and units: world frame z up, metres, radians. ``T_world_tcp`` is the
TCP pose following :class:`~asmteach.core.models.HandSpec` (z = approach out of
the palm, y = jaw axis). An arm's configuration is a ``(dof,)`` array of joint
positions in radians, in the order of :meth:`RobotModel.joint_names`.
"""

from __future__ import annotations

import abc
import copy
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Self

import numpy as np

if TYPE_CHECKING:  # interfaces imports this module; these names are only annotations here
    from asmteach.core.interfaces import IKResult, Obstacle, PartModel
    from asmteach.core.models import HandSpec, TablePlane, Trajectory
    from asmteach.core.perception.depth_camera import KinectSettings  # loads open3d: annotations only

__all__ = ["Attachment", "PlanningScene", "RobotModel", "World", "WristCamera"]


# ---------------------------------------------------------------- kinematics
class RobotModel(abc.ABC):
    """Stateless kinematics of a robot with named arms (``"left"``, ``"right"``, ``"main"``) and one hand each."""

    @property
    @abc.abstractmethod
    def arms(self) -> list[str]:
        """Names of the arms, preferred first."""

    @property
    @abc.abstractmethod
    def hand(self) -> HandSpec:
        """Geometry of the gripper on every arm (metres, in the TCP frame)."""

    @abc.abstractmethod
    def joint_names(self, arm: str) -> list[str]:
        """Joint names of ``arm`` in configuration order."""

    @abc.abstractmethod
    def joint_limits(self, arm: str) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` joint limits of ``arm``, each ``(dof,)`` radians (metres for a prismatic joint)."""

    @abc.abstractmethod
    def home(self, arm: str) -> np.ndarray:
        """A safe resting configuration of ``arm``, ``(dof,)``; the arms start there after a world reset."""

    @abc.abstractmethod
    def fk(self, arm: str, q: np.ndarray) -> np.ndarray:
        """``T_world_tcp`` ``(4, 4)`` of ``arm`` at ``q`` ``(dof,)``."""

    @abc.abstractmethod
    def ik(self, arm: str, T_world_tcp: np.ndarray, q_seed: np.ndarray | None = None) -> IKResult:
        """A ``q`` with ``fk(arm, q) == T_world_tcp`` ``(4, 4)``, near ``q_seed`` when given; never raises on failure.

        The jaw is symmetric: a robot may return the solution of the TCP turned
        by pi about its approach axis and say so with ``IKResult.flipped``.
        """

    def ik_many(self, arm: str, T_world_tcp: np.ndarray, q_seed: np.ndarray | None = None) -> list[IKResult]:
        """:meth:`ik` of ``(n, 4, 4)`` targets; ``q_seed`` is one ``(dof,)`` seed or ``(n, dof)`` seeds.

        Planners screen hundreds of grasps this way; robots with a batched
        solver override it (the default solves one target after the other).
        """
        T = np.asarray(T_world_tcp, float).reshape(-1, 4, 4)
        seeds = [None] * len(T) if q_seed is None else np.broadcast_to(q_seed, (len(T), np.shape(q_seed)[-1]))
        return [self.ik(arm, t, s) for t, s in zip(T, seeds, strict=True)]

    def speed_limits(self, arm: str) -> np.ndarray:
        """Joint speed limits ``(dof,)`` in rad/s (m/s for a prismatic joint) that trajectories must respect."""
        return np.ones(len(self.joint_names(arm)))

    def acceleration_limits(self, arm: str) -> np.ndarray | None:
        """Joint acceleration limits ``(dof,)`` in rad/s^2, or ``None`` when the robot states none (planners then
        use their own setting)."""
        return None


# ---------------------------------------------------------------- planning scene
@dataclass(frozen=True)
class Attachment:
    """A part held by a hand: its pose ``T_tcp_part`` ``(4, 4)`` in the TCP frame and the jaw opening ``width``
    (metres; ``None``: the fingers stay open)."""

    part: PartModel
    T_tcp_part: np.ndarray
    width: float | None = None


class PlanningScene(abc.ABC):
    """What collision checking sees: every arm's configuration, the obstacles and the held parts.

    An immutable value: the ``with_*`` methods return a new scene of the same
    type and leave this one as it was, so a planner can keep the scenes of
    earlier keyframes and hand the caller back the one it ended with. The
    table (and anything else the robot models itself) is always there and is
    not among :attr:`obstacles`.

    A robot implements the queries (:meth:`in_collision`, :meth:`clearance`,
    optionally :meth:`collision_reports`) in a subclass; the value handling is
    done here. Subclasses may keep references to the robot's checker, which
    they bring to this scene's state before answering.
    """

    def __init__(
        self,
        configuration: Mapping[str, np.ndarray],
        obstacles: Sequence[Obstacle] = (),
        attached: Mapping[str, Attachment] | None = None,
    ) -> None:
        self._configuration = {arm: _frozen(q) for arm, q in configuration.items()}
        self._obstacles = tuple(obstacles)
        self._attached = dict(attached or {})

    # -- the value
    @property
    def configuration(self) -> Mapping[str, np.ndarray]:
        """Arm name -> its configuration ``(dof,)`` radians (read-only arrays)."""
        return MappingProxyType(self._configuration)

    @property
    def obstacles(self) -> tuple[Obstacle, ...]:
        """The static obstacles (meshes at world poses) besides the table."""
        return self._obstacles

    @property
    def attached(self) -> Mapping[str, Attachment]:
        """Arm name -> the part its hand holds (arms holding nothing are absent)."""
        return MappingProxyType(self._attached)

    @property
    def table(self) -> Obstacle | None:
        """The table this scene checks against, as an obstacle named ``"table"`` (a box whose top face is the
        table top, world frame), for planners that check their own geometry against it; ``None`` when the
        robot models no table."""
        return None

    def with_configuration(self, arm: str, q: np.ndarray) -> Self:
        """This scene with ``arm`` at ``q`` ``(dof,)`` radians."""
        new = copy.copy(self)
        new._configuration = {**self._configuration, arm: _frozen(q)}
        return new

    def with_obstacles(self, obstacles: Sequence[Obstacle]) -> Self:
        """This scene with ``obstacles`` instead of its obstacles (the table stays)."""
        new = copy.copy(self)
        new._obstacles = tuple(obstacles)
        return new

    def with_attached(
        self, arm: str, part: PartModel | None, T_tcp_part: np.ndarray | None = None, *, width: float | None = None
    ) -> Self:
        """This scene with ``part`` held by ``arm`` at ``T_tcp_part`` (TCP frame), the jaw ``width`` metres open
        (the fingers are checked closed on the part, where they really are); ``part=None`` empties the hand."""
        new = copy.copy(self)
        held = dict(self._attached)
        if part is None:
            held.pop(arm, None)
        else:
            if T_tcp_part is None:
                raise ValueError(f"with_attached({arm!r}, {part.name!r}): T_tcp_part is required")
            held[arm] = Attachment(part, _frozen(T_tcp_part), None if width is None else float(width))
        new._attached = held
        return new

    # -- the queries
    @abc.abstractmethod
    def in_collision(self, arm: str, qs: np.ndarray, *, ignore: Sequence[str] = ()) -> np.ndarray:
        """Batch check of ``arm`` at ``(n, dof)`` configurations (the other arms where this scene has them)
        -> ``(n,)`` bool, True = collides.

        ``ignore`` names obstacles whose contact with the held part is intended (an insertion).
        """

    @abc.abstractmethod
    def clearance(self, arm: str, qs: np.ndarray, upto: float = np.inf) -> np.ndarray:
        """Batch distance (metres) from ``arm``, its hand and held part to everything else; ``(n,)``.

        Distances of ``upto`` or more may come back as ``upto`` (a cost map
        that is flat beyond some clearance need not pay for exact large ones).
        """

    def collision_reports(self, arm: str, qs: np.ndarray) -> list[list[tuple[str, str]]]:
        """Per configuration of ``qs`` ``(n, dof)``, the pairs ``(robot link, obstacle)`` in contact; for the
        reasons planners give (the default names none)."""
        return [[] for _ in np.atleast_2d(np.asarray(qs, float))]

    def collision_report(self, arm: str, q: np.ndarray) -> list[tuple[str, str]]:
        """:meth:`collision_reports` of one configuration ``(dof,)``."""
        return self.collision_reports(arm, np.asarray(q, float)[None, :])[0]


def _frozen(a: np.ndarray) -> np.ndarray:
    out = np.array(a, dtype=float)
    out.setflags(write=False)
    return out


# ---------------------------------------------------------------- world
@dataclass(frozen=True, eq=False)  # eq=False: numpy arrays have no single truth value to compare by
class WristCamera:
    """A depth camera carried by an arm's hand: ``T_tcp_cam`` ``(4, 4)`` is its OpenCV frame (z forward, y down)
    in the arm's TCP frame (metres), so ``T_world_cam = fk(arm, q) @ T_tcp_cam``; ``sensor`` is its model.

    To put the camera at ``T_world_cam`` ask IK for ``T_world_cam @ inv(T_tcp_cam)`` and refuse an
    ``IKResult.flipped`` solution: the jaw is symmetric but the camera is not (turned by pi about the
    approach it would sit on the hand's other side)."""

    T_tcp_cam: np.ndarray
    sensor: KinectSettings


class World(abc.ABC):
    """The cell the robot acts in: simulated or real. Only the pipeline holds one.

    Use as a context manager so a simulator or a connection is always closed.
    """

    @abc.abstractmethod
    def reset_world(self, table: TablePlane, parts: dict[str, tuple[PartModel, np.ndarray]]) -> None:
        """A fresh world: the table (top at ``table.height``), each part ``name -> (model, T_world_part)``,
        the arms at their home, the hands open and empty."""

    @abc.abstractmethod
    def current(self, arm: str) -> np.ndarray:
        """``arm``'s joint positions ``(dof,)`` radians in the world now (measured, not planned)."""

    @abc.abstractmethod
    def execute(self, trajectory: Trajectory) -> None:
        """Run a time-parametrised trajectory; it must start at :meth:`current`.

        Bad trajectories (wrong joints, beyond limits, too fast) raise
        :class:`~asmteach.core.errors.UserError` saying what is wrong.
        """

    @abc.abstractmethod
    def grip(self, arm: str, close: bool, part: str | None = None) -> bool:
        """Close the hand on ``part`` (True when it holds it) or open it (releasing what it held; False)."""

    @abc.abstractmethod
    def part_pose(self, name: str) -> np.ndarray:
        """Ground truth ``T_world_part`` ``(4, 4)`` of a part of :meth:`reset_world` (where it is now)."""

    @abc.abstractmethod
    def sense_depth(self) -> tuple[np.ndarray, np.ndarray]:
        """The depth camera: ``(depth image (h, w) metres, NaN = no return; cloud (n, 3) world frame)``.

        The cloud holds the table and the parts, not the robot (a self-filter).
        """

    def camera_pose(self) -> np.ndarray:
        """``T_world_cam`` ``(4, 4)`` of the depth camera (OpenCV camera frame: z forward, y down).

        Optional: a world that does not know it raises :class:`NotImplementedError`
        and detectors fall back on their own viewpoint setting.
        """
        raise NotImplementedError(f"{type(self).__name__} does not know its camera pose")

    def depth_views(self) -> int:
        """How many depth cameras the world has; a world with more takes ``view=i`` in :meth:`sense_depth`
        and :meth:`camera_pose` (0 is the one above). Optional: one unless a world says otherwise."""
        return 1

    def wrist_cameras(self) -> list[str]:
        """The arms whose hand carries a depth camera (:meth:`wrist_camera`, :meth:`sense_wrist`); none by default."""
        return []

    def wrist_camera(self, arm: str) -> WristCamera:
        """Where ``arm``'s wrist camera sits on the hand and what sensor it is.

        Optional: only arms of :meth:`wrist_cameras` have one; the default raises :class:`NotImplementedError`.
        """
        raise NotImplementedError(f"{type(self).__name__} has no wrist camera")

    def sense_wrist(self, arm: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A frame of ``arm``'s wrist camera at the arm's configuration now: ``(depth image (h, w) metres, NaN =
        no return; cloud (n, 3) world frame of the table and the parts, not the robot (a self-filter, as
        :meth:`sense_depth`); T_world_cam (4, 4))``.

        Optional: the default raises :class:`NotImplementedError`.
        """
        raise NotImplementedError(f"{type(self).__name__} has no wrist camera")

    def sense_rgb(self) -> np.ndarray:
        """An RGB image ``(h, w, 3) uint8`` of the cell (the run's animation is made of them).

        Optional: a world without a colour camera raises :class:`NotImplementedError`
        and the run records no animation.
        """
        raise NotImplementedError(f"{type(self).__name__} has no colour camera")

    def close(self) -> None:  # noqa: B027 - a world without resources has nothing to release
        """Release the simulator, the connection and any other resources."""

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
