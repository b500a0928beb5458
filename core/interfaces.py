"""The roles of the pipeline as small abstract classes.

A plugin is a subclass of one of these, registered under the role's
entry-point group (see :mod:`asmteach.core.registry`). Each plugin declares
its own pydantic ``Settings`` model (unknown keys forbidden); the config names
the plugin and carries those settings, and the registry builds the plugin as
``PluginClass(settings, seed=seed)``.

Frames: ``T_world_*`` poses are in the world frame (z up, metres); parts are
described in their own part frame (see :class:`PartModel`).
"""

from __future__ import annotations

import abc
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import trimesh

from asmteach.core.failures import FailureKind
from asmteach.core.models import (
    AssemblyTask,
    CameraIntrinsics,
    Correction,
    Detection,
    Grasp,
    HandSpec,
    PartSpec,
    Plan,
    StrictModel,
    TablePlane,
    Trajectory,
)

__all__ = [
    "ROLES",
    "AssemblyPlanner",
    "AssemblyProblem",
    "AssemblyResult",
    "Corrector",
    "Detector",
    "GraspPlanner",
    "IKResult",
    "MotionPlanner",
    "MotionResult",
    "Obstacle",
    "PartModel",
    "Plugin",
    "Robot",
    "Teacher",
]


class NoSettings(StrictModel):
    """Settings of a plugin that takes none."""


class Plugin(abc.ABC):  # noqa: B024 - abstract by intent; roles add the abstract methods
    """Base of every plugin: holds validated settings and the run's seed."""

    Settings: ClassVar[type[StrictModel]] = NoSettings
    """The plugin's own settings model; override in subclasses."""

    def __init__(self, settings: StrictModel | dict[str, Any] | None = None, *, seed: int = 0) -> None:
        if settings is None:
            settings = {}
        if isinstance(settings, dict):
            settings = self.Settings.model_validate(settings)
        self.settings = settings
        self.seed = int(seed)

    def rng(self, *salt: int) -> np.random.Generator:
        """A generator derived from the run seed (plus optional salt), never global state."""
        return np.random.default_rng([self.seed, *salt])


@dataclass
class PartModel:
    """A part ready for computation: its spec, mesh and mass properties.

    ``mesh`` is a watertight ``trimesh.Trimesh`` in the part frame (metres);
    ``center_of_mass`` is in the part frame; ``mass`` in kg.

    A part given as a scan (a PCD/PLY point cloud, :func:`asmteach.core.parts.build_cloud_part`) has
    ``points`` ((n, 3), part frame = the file's frame, metres) and ``scan_viewpoint`` (the scanner's centre
    in the part frame, metres, or ``None`` when unknown; it orients the scan's normals). Its ``mesh`` is
    then only the points' convex hull, a stand-in for size and bounds: a detector that needs the surface
    (rendered views, ray casting) cannot use such a part; one that can says so with ``takes_cloud_models``.
    """

    spec: PartSpec
    mesh: trimesh.Trimesh
    mass: float
    center_of_mass: np.ndarray
    source_hash: str = ""
    points: np.ndarray | None = None
    scan_viewpoint: np.ndarray | None = None

    @property
    def name(self) -> str:
        return self.spec.name


# ---------------------------------------------------------------- teaching
class Teacher(Plugin):
    """Learns an :class:`AssemblyTask` from RGB frames of a human demonstration."""

    @abc.abstractmethod
    def teach(
        self,
        frames: Sequence[np.ndarray],
        camera: CameraIntrinsics,
        task: AssemblyTask,
    ) -> AssemblyTask:
        """Estimate ``T_A_B`` and ``v_a`` from ``frames``.

        Parameters
        ----------
        frames : sequence of ``(h, w, 3) uint8`` BGR images, in time order.
        camera : intrinsics of the camera that took them.
        task : the parts (with their markers); its ``T_A_B``/``v_a`` are a prior
            at most and must not be copied into the result.

        Returns the task with the learned ``T_A_B``, ``v_a`` and ``evidence``.
        Raises :class:`~asmteach.core.errors.UserError` when the frames cannot
        support an estimate (no marker of a part seen, too few frames).
        """

    def demonstrate(
        self,
        task: AssemblyTask,
        demo: dict[str, Any],
        camera_file: Path | None = None,
        out_dir: Path | None = None,
    ) -> tuple[list[np.ndarray], CameraIntrinsics]:
        """Synthetic demonstration frames of ``task`` (its true ``T_A_B``/``v_a``) for simulated runs.

        ``demo`` holds the renderer's settings (the config's ``demo`` section);
        ``camera_file`` optional intrinsics; when ``out_dir`` is given the
        frames and their ground truth are written there too. Optional: a
        teacher that cannot render raises ``NotImplementedError``.
        """
        raise NotImplementedError(f"{type(self).__name__} cannot render demonstrations")


# ---------------------------------------------------------------- detection
class Detector(Plugin):
    """Finds the pose of one known part in a depth point cloud."""

    takes_cloud_models: ClassVar[bool] = False
    """Whether the detector works from a part given as a scan (``PartModel.points``), not only a mesh."""

    def prepare(self, part: PartModel) -> None:
        """Build or load per-part data (view databases); called once per part."""

    @abc.abstractmethod
    def detect(
        self,
        cloud: np.ndarray,
        part: PartModel,
        table: TablePlane | None = None,
        viewpoint: np.ndarray | None = None,
    ) -> Detection:
        """Detect ``part`` in ``cloud``.

        Parameters
        ----------
        cloud : ``(n, 3) float`` points in the world frame (metres, z up),
            the table below the part. NaN rows are ignored.
        part : the part to find.
        table : the table plane when known; otherwise the detector fits it.
        viewpoint : ``(3,)`` camera centre in the world frame (metres) when
            known (view-dependent descriptors need it); otherwise the
            detector's own setting.

        Returns a :class:`Detection` with ``rough`` set, or ``found=False`` and
        a ``reason``; never a wrong pose reported as found when verification fails.
        """


class Corrector(Plugin):
    """Turns a rough pose into one consistent with physical constraints."""

    @abc.abstractmethod
    def correct(
        self,
        T_world_part: np.ndarray,
        part: PartModel,
        table: TablePlane,
        cloud: np.ndarray | None = None,
        viewpoint: np.ndarray | None = None,
    ) -> Correction:
        """Correct a rough ``(4, 4)`` pose of ``part`` resting on ``table``.

        ``cloud`` (world frame) is the observed segment of the part, if the
        corrector refines against it; ``viewpoint`` the ``(3,)`` camera centre
        in the world frame (metres) when known.
        """


# ---------------------------------------------------------------- grasps
class GraspPlanner(Plugin):
    """Plans parallel-jaw grasps of a part in free space (part frame)."""

    @abc.abstractmethod
    def plan(self, part: PartModel, hand: HandSpec) -> list[Grasp]:
        """Return grasps sorted by decreasing score, ids ``0..n-1``."""


# ---------------------------------------------------------------- motion
@dataclass
class MotionResult:
    """Outcome of a joint-space motion query; ``path`` is ``(n, dof)`` radians."""

    success: bool
    path: np.ndarray | None = None
    reason: str | None = None
    stats: dict[str, Any] = field(default_factory=dict)
    kind: FailureKind | None = None
    """Why it failed (None on success): callers branch on this, ``reason`` is for people."""


class MotionPlanner(Plugin):
    """Plans a collision-free joint path between two configurations.

    The planner never touches a simulator: it is fed callables, so it can be
    tested headless with any validity function.
    """

    @abc.abstractmethod
    def plan(
        self,
        start: np.ndarray,
        goal: np.ndarray,
        *,
        lower: np.ndarray,
        upper: np.ndarray,
        is_valid: Callable[[np.ndarray], bool],
        cost: Callable[[np.ndarray], float] | None = None,
        time_limit: float = 5.0,
    ) -> MotionResult:
        """Find a path from ``start`` to ``goal`` (``(dof,)`` radians) within joint bounds.

        ``is_valid(q)`` says whether a configuration is collision-free;
        ``is_valid`` and ``cost`` may also carry a vectorised ``.batch(qs)``
        for ``(n, dof)`` configurations, which planners may use to check
        whole edges at once (see ``asmteach.core.trajectory.batch``);
        ``cost(q)`` is the state cost a cost-aware planner minimises (higher is
        worse, e.g. inverse clearance). Returns a typed result carrying the
        reason of a failure (``"timeout after 5.0 s"``, ``"start in collision"``).
        """


# ---------------------------------------------------------------- robot
@dataclass
class IKResult:
    """Inverse kinematics outcome. ``residual_*`` are the final errors."""

    success: bool
    q: np.ndarray | None
    residual_pos: float = float("inf")
    residual_rot: float = float("inf")
    reason: str | None = None
    flipped: bool = False
    """True when the solution uses the other finger order of the symmetric jaw."""


@dataclass
class Obstacle:
    """A static collision object of the world: a mesh at a world pose."""

    name: str
    mesh: trimesh.Trimesh
    T_world: np.ndarray


class Robot(Plugin):
    """A robot with kinematics, collision checking and (optionally) a simulator.

    Arms are named (``"left"``, ``"right"``); each arm's configuration is a
    ``(dof,)`` array of joint positions in radians in the order of
    :meth:`joint_names`. The TCP follows :class:`HandSpec`'s frame.
    Use as a context manager so a simulator is always closed::

        with registry.create("robots", "nextage_pybullet", settings) as robot:
            ...
    """

    # -- description
    @property
    @abc.abstractmethod
    def arms(self) -> list[str]:
        """Names of the arms, preferred first."""

    @property
    @abc.abstractmethod
    def hand(self) -> HandSpec:
        """Geometry of the gripper on every arm."""

    @abc.abstractmethod
    def joint_names(self, arm: str) -> list[str]:
        """Joint names of ``arm`` in configuration order."""

    @abc.abstractmethod
    def joint_limits(self, arm: str) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` joint limits of ``arm`` in radians."""

    @abc.abstractmethod
    def home(self, arm: str) -> np.ndarray:
        """A safe resting configuration of ``arm``."""

    # -- kinematics
    @abc.abstractmethod
    def fk(self, arm: str, q: np.ndarray) -> np.ndarray:
        """``T_world_tcp`` (4x4) of ``arm`` at ``q``."""

    @abc.abstractmethod
    def ik(self, arm: str, T_world_tcp: np.ndarray, q_seed: np.ndarray | None = None) -> IKResult:
        """Solve for ``q`` with ``fk(arm, q) == T_world_tcp``; never raises on failure."""

    def ik_many(self, arm: str, T_world_tcp: np.ndarray, q_seed: np.ndarray | None = None) -> list[IKResult]:
        """:meth:`ik` of ``(n, 4, 4)`` targets; ``q_seed`` is one ``(dof,)`` seed or ``(n, dof)`` seeds.

        Planners screen hundreds of grasps this way; robots with a batched
        solver override it (the default solves one target after the other).
        """
        T = np.asarray(T_world_tcp, float).reshape(-1, 4, 4)
        seeds = [None] * len(T) if q_seed is None else np.broadcast_to(q_seed, (len(T), np.shape(q_seed)[-1]))
        return [self.ik(arm, t, s) for t, s in zip(T, seeds, strict=True)]

    # -- collision
    @abc.abstractmethod
    def set_obstacles(self, obstacles: Sequence[Obstacle]) -> None:
        """Replace the static world used for collision checking (the table is always there)."""

    @abc.abstractmethod
    def attach(self, arm: str, part: PartModel | None, T_tcp_part: np.ndarray | None = None, *,
               width: float | None = None) -> None:
        """Attach ``part`` to ``arm``'s TCP for collision checking (``None`` detaches).

        ``width`` (metres) is the jaw opening while holding: the fingers are
        checked closed on the part, where they really are (``None``: left as they are).
        """

    @abc.abstractmethod
    def in_collision(self, arm: str, qs: np.ndarray, *, ignore: Sequence[str] = ()) -> np.ndarray:
        """Batch check: ``(n, dof)`` configurations -> ``(n,)`` bool (True = collides).

        ``ignore`` names obstacles whose contact with the held part is intended.
        """

    @abc.abstractmethod
    def clearance(self, arm: str, qs: np.ndarray, upto: float = np.inf) -> np.ndarray:
        """Batch distance (metres) from the arm, hand and held part to the world; ``(n,)``.

        Distances of ``upto`` or more may come back as ``upto`` (a cost map
        that is flat beyond some clearance need not pay for exact large ones).
        """

    def collision_report(self, arm: str, q: np.ndarray) -> list[tuple[str, str]]:
        """Pairs ``(robot link, obstacle)`` in contact at ``q``; for error messages."""
        return []

    def collision_reports(self, arm: str, qs: np.ndarray) -> list[list[tuple[str, str]]]:
        """:meth:`collision_report` of each of ``qs`` ``(n, dof)``; a robot with a batched checker may do it in
        one pass (the regrasp planner explains every grasp it rejects for a collision)."""
        return [self.collision_report(arm, q) for q in np.atleast_2d(np.asarray(qs, float))]

    # -- simulation (robots without a simulator may leave these unimplemented)
    def reset_world(self, table: TablePlane, parts: dict[str, tuple[PartModel, np.ndarray]]) -> None:
        """Start a fresh simulated world: the table and parts at ``T_world_part``."""
        raise NotImplementedError(f"{type(self).__name__} has no simulator")

    def execute(self, trajectory: Trajectory) -> None:
        """Run a time-parametrised trajectory in the simulator."""
        raise NotImplementedError(f"{type(self).__name__} has no simulator")

    def grip(self, arm: str, close: bool, part: str | None = None) -> bool:
        """Close (holding ``part``) or open the gripper; returns True when holding."""
        raise NotImplementedError(f"{type(self).__name__} has no simulator")

    def part_pose(self, name: str) -> np.ndarray:
        """Simulated ground-truth ``T_world_part`` of a spawned part."""
        raise NotImplementedError(f"{type(self).__name__} has no simulator")

    def speed_limits(self, arm: str) -> np.ndarray:
        """Joint speed limits ``(dof,)`` in rad/s that trajectories for ``arm`` must respect."""
        return np.ones(len(self.joint_names(arm)))

    def sense_depth(self) -> tuple[np.ndarray, np.ndarray]:
        """Simulated depth camera: ``(depth image (h, w) metres, cloud (n, 3) world frame)``."""
        raise NotImplementedError(f"{type(self).__name__} has no depth camera")

    def camera_pose(self) -> np.ndarray:
        """``T_world_cam`` (4x4, metres, OpenCV camera frame: z forward, y down) of the depth camera."""
        raise NotImplementedError(f"{type(self).__name__} has no depth camera")

    def verify_plan(self, plan: Plan, parts: dict[str, tuple[PartModel, np.ndarray]], table: TablePlane,
                    resolution: float = 0.005) -> Any:
        """Re-check ``plan`` with a collision model independent of the planner's.

        ``parts`` maps a part name to its model and start pose ``T_world_part``
        (metres); arms start at :meth:`home`; ``resolution`` is the largest
        motion (metres) of any robot or held-part point between checks. Returns
        a pydantic model with at least ``ok: bool``, ``collisions: list`` and
        ``summary() -> str``.
        """
        raise NotImplementedError(f"{type(self).__name__} has no independent plan check")

    def close(self) -> None:
        """Release the simulator and any other resources."""

    def __enter__(self) -> Robot:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# ---------------------------------------------------------------- assembly planning
@dataclass
class AssemblyProblem:
    """What the assembly planner is asked: put B into A (world frame, metres).

    ``T_world_a`` / ``T_world_b`` are the parts' start poses as detected and
    corrected; grasps are in each part's frame.
    """

    part_a: PartModel
    part_b: PartModel
    task: AssemblyTask
    T_world_a: np.ndarray
    T_world_b: np.ndarray
    grasps_a: list[Grasp]
    grasps_b: list[Grasp]
    table: TablePlane


@dataclass
class AssemblyResult:
    """A plan for both parts, or how far planning got and why it stopped.

    ``plan`` holds the timed segments found so far even on failure;
    ``failed_at`` names the part and keyframe; ``T_world_a_goal`` and
    ``T_world_b_goal`` are where the parts are meant to end.
    """

    success: bool
    plan: Plan
    reason: str | None = None
    failed_at: str | None = None
    T_world_a_goal: np.ndarray | None = None
    T_world_b_goal: np.ndarray | None = None
    details: dict[str, Any] = field(default_factory=dict)
    """Planner-specific data for figures (graphs, keyframe searches)."""


class AssemblyPlanner(Plugin):
    """Plans grasps, regrasps and arm motions that assemble B into A."""

    @abc.abstractmethod
    def plan(
        self,
        problem: AssemblyProblem,
        robot: Robot,
        motion_planner: MotionPlanner,
        *,
        progress: Callable[[str], None] | None = None,
    ) -> AssemblyResult:
        """Plan with ``robot``'s kinematics and collision model; never moves its simulator."""

    def plan_insertion(
        self,
        problem: AssemblyProblem,
        robot: Robot,
        motion_planner: MotionPlanner,
        *,
        T_world_a: np.ndarray,
        progress: Callable[[str], None] | None = None,
    ) -> AssemblyResult:
        """Optional: B's part of the plan only, into A already standing at ``T_world_a`` (world, metres).

        The run calls it when A, seen again at its goal, is not quite where the
        plan put it, to aim B at the A that is there. The arms start where they
        are now. Planners that cannot do this raise :class:`NotImplementedError`
        and the run goes on with the plan it has.
        """
        raise NotImplementedError

    def write_figures(self, result: AssemblyResult, out_dir: Path) -> dict[str, Path]:
        """Optional figures of a result (e.g. the regrasp graph); name -> PNG written atomically."""
        return {}


ROLES: dict[str, type[Plugin]] = {
    "teachers": Teacher,
    "detectors": Detector,
    "correctors": Corrector,
    "grasp_planners": GraspPlanner,
    "motion_planners": MotionPlanner,
    "robots": Robot,
    "assembly_planners": AssemblyPlanner,
}
"""Entry-point group suffix (``asmteach.<suffix>``) -> the interface its plugins implement."""
