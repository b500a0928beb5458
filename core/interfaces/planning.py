"""The planning roles: :class:`GraspPlanner`, :class:`MotionPlanner` (with :class:`MotionResult`) and
:class:`AssemblyPlanner` (with :class:`AssemblyProblem` and :class:`AssemblyResult`).

Frames: ``T_world_*`` poses are in the world frame (z up, metres); grasps are in their part's frame;
joint values are radians.
"""

from __future__ import annotations

import abc
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from asmteach.core.failures import FailureCause, FailureKind
from asmteach.core.interfaces.part_model import PartModel
from asmteach.core.interfaces.plugin import Plugin
from asmteach.core.interfaces.robot import Robot
from asmteach.core.models import AssemblyTask, Grasp, HandSpec, Plan, TablePlane
from asmteach.core.robot import PlanningScene

__all__ = ["AssemblyPlanner", "AssemblyProblem", "AssemblyResult", "GraspPlanner", "MotionPlanner", "MotionResult"]


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
    ``T_world_b_goal`` are where the parts are meant to end; ``cause`` says
    why planning failed as a kind the run records (``reason`` is for people).
    """

    success: bool
    plan: Plan
    reason: str | None = None
    failed_at: str | None = None
    T_world_a_goal: np.ndarray | None = None
    T_world_b_goal: np.ndarray | None = None
    details: dict[str, Any] = field(default_factory=dict)
    """Planner-specific data for figures (graphs, keyframe searches)."""
    cause: FailureCause | None = None
    """Why it failed (None on success, or a planner that does not say; the run then records ``other``):
    ``no_grasp`` (no feasible grasp at the start or goal), ``regrasp_graph`` (no connected keyframe path, or the
    search's budget spent), ``motion`` (keyframes found, a motion between them not planned)."""
    scene: PlanningScene | None = None
    """The planning scene the plan ends in (arms, held parts, obstacles after its last segment), for a caller
    that plans on from there; None when the planner does not say."""


class AssemblyPlanner(Plugin):
    """Plans grasps, regrasps and arm motions that assemble B into A."""

    @abc.abstractmethod
    def plan(
        self,
        problem: AssemblyProblem,
        robot: Robot,
        motion_planner: MotionPlanner,
        *,
        scene: PlanningScene | None = None,
        progress: Callable[[str], None] | None = None,
    ) -> AssemblyResult:
        """Plan with ``robot``'s kinematics, starting in ``scene`` (default ``robot.scene``).

        The planner checks collisions in scene values it derives from that one and
        returns the scene the plan ends in (:attr:`AssemblyResult.scene`); it
        changes neither ``robot.scene`` nor the robot's simulator.
        """

    def plan_insertion(
        self,
        problem: AssemblyProblem,
        robot: Robot,
        motion_planner: MotionPlanner,
        *,
        T_world_a: np.ndarray,
        scene: PlanningScene | None = None,
        progress: Callable[[str], None] | None = None,
    ) -> AssemblyResult:
        """Optional: B's part of the plan only, into A already standing at ``T_world_a`` (world, metres).

        The run calls it when A, seen again at its goal, is not quite where the
        plan put it, to aim B at the A that is there. The arms start where
        ``scene`` (default ``robot.scene``) has them: where they are now. Planners
        that cannot do this raise :class:`NotImplementedError` and the run goes
        on with the plan it has.
        """
        raise NotImplementedError

    def write_figures(self, result: AssemblyResult, out_dir: Path) -> dict[str, Path]:
        """Optional figures of a result (e.g. the regrasp graph); name -> PNG written atomically."""
        return {}
