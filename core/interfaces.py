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
from typing import Any, ClassVar, Self

import numpy as np
import trimesh

from asmteach.core.errors import UserError
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
)
from asmteach.core.robot import PlanningScene, RobotModel

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

    DemoSettings: ClassVar[type[StrictModel] | None] = None
    """The model of the run config's ``demo`` section, for a teacher that renders demonstrations
    (:meth:`demonstrate`); ``None``: the teacher takes no ``demo`` section (one given is an error)."""

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
    """Inverse kinematics outcome: ``q`` ``(dof,)`` radians when solved; ``residual_pos`` (metres) and
    ``residual_rot`` (radians) are the final TCP errors; ``reason`` says why it failed."""

    success: bool
    q: np.ndarray | None
    residual_pos: float = float("inf")
    residual_rot: float = float("inf")
    reason: str | None = None
    flipped: bool = False
    """True when the solution uses the other finger order of the symmetric jaw."""


@dataclass
class Obstacle:
    """A static collision object of the world: ``mesh`` (metres, its own frame) at ``T_world`` ``(4, 4)``."""

    name: str
    mesh: trimesh.Trimesh
    T_world: np.ndarray


class Robot(Plugin, RobotModel):
    """The robot the config's ``robot:`` section builds: a :class:`RobotModel` with its current planning scene.

    The contracts themselves are in :mod:`asmteach.core.robot`: planners need
    the :class:`RobotModel` and a :class:`PlanningScene` (:attr:`scene`); the
    pipeline also needs a :class:`World` to run in, so a robot plugin the
    pipeline can run subclasses both (``class MyRobot(Robot, World)``).
    Use as a context manager so a simulator is always closed::

        with registry.create("robots", "nextage_pybullet", settings) as robot:
            ...

    The methods below that change the scene (:meth:`set_obstacles`,
    :meth:`attach`, :meth:`set_configuration`) replace :attr:`scene` with a new
    value and never move the world; the queries ask :attr:`scene`. They are
    kept for planners written against one mutable robot; new code passes
    :class:`PlanningScene` values instead.
    """

    _scene: PlanningScene | None = None

    # -- the planning scene
    @property
    def scene(self) -> PlanningScene:
        """The robot's planning scene now: after a world reset, the arms at home, no obstacles, empty hands."""
        if self._scene is None:
            raise NotImplementedError(f"{type(self).__name__} keeps no planning scene (set self.scene when built)")
        return self._scene

    @scene.setter
    def scene(self, scene: PlanningScene) -> None:
        self._scene = scene

    def current(self, arm: str) -> np.ndarray:
        """Where ``arm`` is now ``(dof,)`` radians: for a robot that is also a :class:`World`, the world's
        measured joints (:meth:`World.current`); otherwise its configuration in :attr:`scene`."""
        return np.array(self.scene.configuration[arm], dtype=float)

    def set_configuration(self, arm: str, q: np.ndarray) -> None:
        """:attr:`scene` with ``arm`` at ``q`` ``(dof,)`` radians (within the joint limits); the world stays."""
        q = np.asarray(q, dtype=float)
        lo, hi = self.joint_limits(arm)
        if q.shape != lo.shape or np.any(q < lo - 1e-6) or np.any(q > hi + 1e-6):
            raise UserError(
                f"configuration {np.round(q, 4).tolist()} of arm {arm!r} is outside its joint limits "
                f"[{np.round(lo, 4).tolist()}, {np.round(hi, 4).tolist()}]"
            )
        self.scene = self.scene.with_configuration(arm, np.clip(q, lo, hi))

    def set_obstacles(self, obstacles: Sequence[Obstacle]) -> None:
        """:attr:`scene` with ``obstacles`` (the table is always there)."""
        self.scene = self.scene.with_obstacles(obstacles)

    def attach(
        self, arm: str, part: PartModel | None, T_tcp_part: np.ndarray | None = None, *, width: float | None = None
    ) -> None:
        """:attr:`scene` with ``part`` held by ``arm`` (see :meth:`PlanningScene.with_attached`)."""
        self.scene = self.scene.with_attached(arm, part, T_tcp_part, width=width)

    def in_collision(self, arm: str, qs: np.ndarray, *, ignore: Sequence[str] = ()) -> np.ndarray:
        """:meth:`PlanningScene.in_collision` of :attr:`scene`: ``(n, dof)`` -> ``(n,)`` bool."""
        return self.scene.in_collision(arm, qs, ignore=ignore)

    def clearance(self, arm: str, qs: np.ndarray, upto: float = np.inf) -> np.ndarray:
        """:meth:`PlanningScene.clearance` of :attr:`scene`: ``(n, dof)`` -> ``(n,)`` metres."""
        return self.scene.clearance(arm, qs, upto)

    def collision_report(self, arm: str, q: np.ndarray) -> list[tuple[str, str]]:
        """:meth:`PlanningScene.collision_report` of :attr:`scene`."""
        return self.scene.collision_report(arm, q)

    def collision_reports(self, arm: str, qs: np.ndarray) -> list[list[tuple[str, str]]]:
        """:meth:`PlanningScene.collision_reports` of :attr:`scene`."""
        return self.scene.collision_reports(arm, qs)

    # -- an independent check
    def verify_plan(
        self, plan: Plan, parts: dict[str, tuple[PartModel, np.ndarray]], table: TablePlane, resolution: float = 0.005
    ) -> Any:
        """Re-check ``plan`` with a collision model independent of the planner's.

        ``parts`` maps a part name to its model and start pose ``T_world_part``
        (metres); arms start at :meth:`home`; ``resolution`` is the largest
        motion (metres) of any robot or held-part point between checks. Returns
        a pydantic model with at least ``ok: bool``, ``collisions: list`` and
        ``summary() -> str``. Optional: :class:`NotImplementedError` when the
        robot has no second collision model (the run then skips the re-check).
        """
        raise NotImplementedError(f"{type(self).__name__} has no independent plan check")

    def close(self) -> None:
        """Release the simulator and any other resources."""

    def __enter__(self) -> Self:
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
