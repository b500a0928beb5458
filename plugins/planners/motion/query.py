"""What every joint-space planner here shares: settings, typed failures, query checks.

A failed :class:`~asmteach.core.interfaces.MotionResult` carries a readable
``reason`` (e.g. ``"start in collision"``, ``"timeout after 5.0 s"``) and its
typed ``kind`` (a :class:`~asmteach.core.failures.FailureKind`), so callers
branch on the kind and print the reason.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from pydantic import Field

from asmteach.core.errors import UserError
from asmteach.core.failures import FailureKind
from asmteach.core.interfaces import MotionResult
from asmteach.core.models import StrictModel
from asmteach.core.trajectory.interpolate import densify
from asmteach.plugins.planners.motion.shortcut import SegmentChecker, shorten
from asmteach.plugins.planners.motion.space import JointSpace

__all__ = [
    "MotionSettings",
    "check_query",
    "default_range",
    "failure",
    "finish_path",
    "shorten_batched",
]


class MotionSettings(StrictModel):
    """Settings shared by the joint-space planners (radians, seconds)."""

    range: float | None = Field(
        None,
        gt=0,
        description="Step size: the longest tree edge, radians (Euclidean joint-space norm). "
        "None: a fraction of the joint space's diagonal (RRTConnect: 0.2, OMPL's default; T-RRT: 0.05).",
    )
    collision_resolution: float = Field(
        0.01, gt=0, description="Motions are checked every this many radians (Euclidean joint-space norm)."
    )
    simplify: bool = Field(
        True,
        description="Shorten the found path: with the batched shortener when is_valid has a batch (see .batch), "
        "else with OMPL's og.PathSimplifier.",
    )
    simplify_max_time: float | None = Field(
        0.5,
        gt=0,
        description="Seconds for OMPL's simplifier; None runs simplifyMax until no change (deterministic, but "
        "slow with a real robot's collision checks).",
    )
    shortcut_attempts: int = Field(
        10,
        ge=0,
        description="Random shortcuts tried by the batched shortener. Each one kept adds a waypoint, where the "
        "timed path stops: beyond ~10 they cost planning time (70 % of a T-RRT query at 30) and lengthen the "
        "execution, for 2-4 % shorter joint paths",
    )


def failure(kind: FailureKind, detail: str = "", **stats: Any) -> MotionResult:
    """A failed :class:`MotionResult` of ``kind``; ``detail`` is appended to the reason."""
    reason = f"{kind.value} {detail}".strip()
    return MotionResult(success=False, path=None, reason=reason, stats=dict(stats), kind=kind)


def check_query(
    start: np.ndarray,
    goal: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    is_valid: Callable[[np.ndarray], bool],
    settings: MotionSettings,
) -> tuple[JointSpace, np.ndarray, np.ndarray, MotionResult | None]:
    """Build the joint space and check the query's end points.

    Returns ``(space, start, goal, failed)`` where ``failed`` is a typed failure
    result when the start or goal is out of bounds or in collision, else None.
    Raises :class:`UserError` for malformed input (shapes, non-finite values).
    """
    space = JointSpace(lower, upper, is_valid, resolution=settings.collision_resolution)
    q0 = np.asarray(start, dtype=float).reshape(-1)
    q1 = np.asarray(goal, dtype=float).reshape(-1)
    for name, q in (("start", q0), ("goal", q1)):
        if q.shape != (space.dof,) or not np.all(np.isfinite(q)):
            raise UserError(f"motion query: {name} must be {space.dof} finite joint values in radians (got {q.shape})")
    if not space.in_bounds(q0):
        return space, q0, q1, failure(FailureKind.START_OUT_OF_BOUNDS, _bounds_detail(space, q0))
    if not space.in_bounds(q1):
        return space, q0, q1, failure(FailureKind.GOAL_OUT_OF_BOUNDS, _bounds_detail(space, q1))
    if not space.is_valid(q0):
        return space, q0, q1, failure(FailureKind.START_INVALID)
    if not space.is_valid(q1):
        return space, q0, q1, failure(FailureKind.GOAL_INVALID)
    return space, q0, q1, None


def _bounds_detail(space: JointSpace, q: np.ndarray) -> str:
    bad = np.flatnonzero((q < space.lower) | (q > space.upper))
    parts = [f"{i}: {q[i]:.3f} not in [{space.lower[i]:.3f}, {space.upper[i]:.3f}]" for i in bad]
    return "(joints " + ", ".join(parts) + ")"


def default_range(space: JointSpace, settings: MotionSettings, fraction: float = 0.2) -> float:
    """The step size in radians: the setting, or ``fraction`` x the space's diagonal (OMPL uses 0.2)."""
    return float(settings.range) if settings.range is not None else fraction * space.space.getMaximumExtent()


def shorten_batched(
    space: JointSpace,
    path: np.ndarray,
    settings: MotionSettings,
    rng: np.random.Generator,
    *,
    valid_batch: Callable[[np.ndarray], np.ndarray],
    cost_batch: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[np.ndarray, SegmentChecker]:
    """Shorten a found path (radians) with batched checks (:func:`.shortcut.shorten`); also the segment checker,
    which counts its calls.

    With ``cost_batch``, shortcuts may not pass through states costlier than the
    costliest point of the found path (sampled at 4x the motion resolution).
    """
    ceiling = math.inf
    if cost_batch is not None:
        ceiling = float(np.max(cost_batch(densify(path, 4 * space.resolution))))
    segment_ok = SegmentChecker(valid_batch, space.resolution, cost_batch=cost_batch, ceiling=ceiling)
    return shorten(path, segment_ok, rng, attempts=settings.shortcut_attempts), segment_ok


def finish_path(
    space: JointSpace,
    path: np.ndarray,
    settings: MotionSettings,
    cost: Callable[[np.ndarray], float] | None = None,
) -> np.ndarray:
    """Simplify a found path with OMPL's simplifier when the settings ask for it.

    With a ``cost``, shortcuts may not pass through states costlier than the
    costliest waypoint of the found path (see :meth:`JointSpace.simplify`).
    """
    if not settings.simplify:
        return np.asarray(path, dtype=float)
    ceiling = None
    if cost is not None:
        # The worst cost along the path as OMPL's motion validator samples it (every resolution radians),
        # so the path's own segments stay valid under the ceiling and only new shortcuts are constrained.
        ceiling = max(float(cost(q)) for q in densify(path, space.resolution))
    return space.simplify(path, max_time=settings.simplify_max_time, cost=cost, ceiling=ceiling)
