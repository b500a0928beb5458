"""The motions of a transfer, one at a time: free motions from the motion planner, straight TCP lines.

Each raises :class:`MotionFailure` naming the regrasp-graph edge to ban (and,
when no path through it can succeed, the node) so the graph can be searched
again; a free motion's failure is read from the planner's
:class:`~asmteach.core.failures.FailureKind`, never from its reason string.
Collisions are checked on the :class:`~asmteach.core.robot.PlanningScene`
value each motion is given (the robot only lends its kinematics); the motion
planner gets callables that ask that scene.

Frames: ``T_world_*`` 4x4 in metres; joint paths in radians.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from asmteach.core.failures import FailureKind
from asmteach.core.interfaces import MotionPlanner, Obstacle, Robot
from asmteach.core.robot import PlanningScene
from asmteach.core.trajectory.batch import batched, inverse_clearance_cost
from asmteach.core.trajectory.interpolate import densify
from asmteach.plugins.planners.regrasp.settings import AssemblySettings

__all__ = [
    "Checker",
    "MotionFailure",
    "cartesian_path",
    "cleared_scene",
    "first_hit",
    "free_motion",
    "straight_line",
    "world_scene",
]


class MotionFailure(Exception):
    """A keyframe motion failed; ``edge`` is the graph edge to ban, ``node`` a node whose every edge is banned."""

    def __init__(self, edge: tuple[Any, Any], reason: str, node: Any | None = None, timed_out: bool = False) -> None:
        super().__init__(reason)
        self.edge = edge
        self.reason = reason
        self.node = node
        self.timed_out = timed_out  # a wall-clock limit, not the search, ended it: the result depends on the load
        self.scene: PlanningScene | None = None
        """The scene the realisation had reached when it failed (set by the realisation)."""


def cartesian_path(
    robot: Robot, arm: str, q_start: np.ndarray, T_goal: np.ndarray, step: float
) -> tuple[np.ndarray | None, str | None]:
    """Joint path moving the TCP on a straight line to ``T_goal`` (orientation kept; IK per step)."""
    T0 = robot.fk(arm, q_start)
    dist = float(np.linalg.norm(T_goal[:3, 3] - T0[:3, 3]))
    n = max(2, int(np.ceil(dist / step)) + 1)
    path = [np.asarray(q_start, float)]
    for s in np.linspace(0.0, 1.0, n)[1:]:
        T = T_goal.copy()
        T[:3, 3] = (1.0 - s) * T0[:3, 3] + s * T_goal[:3, 3]
        res = robot.ik(arm, T, q_seed=path[-1])
        if not res.success or res.q is None or getattr(res, "flipped", False):
            return None, f"IK fails {s * dist * 1000:.0f} mm along the straight line"
        if np.max(np.abs(res.q - path[-1])) > 0.3:
            return None, "the straight line crosses a singularity or a change of IK branch"
        path.append(np.asarray(res.q, float))
    return np.asarray(path), None


def world_scene(scene: PlanningScene, world: Sequence[Obstacle], *extra: Obstacle) -> PlanningScene:
    """``scene`` with the obstacles ``world`` and ``extra`` without the table, which the robot models itself."""
    return scene.with_obstacles([o for o in world if o.name != "table"] + list(extra))


def cleared_scene(scene: PlanningScene, world: Sequence[Obstacle]) -> PlanningScene:
    """``scene`` with the obstacles of ``world`` (:func:`world_scene`) and no arm holding anything."""
    scene = world_scene(scene, world)
    for arm in list(scene.attached):
        scene = scene.with_attached(arm, None)
    return scene


class Checker:
    """Collision checks of one arm's configurations in one planning scene.

    ``valid`` and ``cost`` answer one configuration and, through ``.batch``,
    many at once (the robot's checker is ~25x cheaper per configuration in a
    batch; T-RRT checks whole edges that way).
    """

    def __init__(self, scene: PlanningScene, arm: str, floor: float = 0.0) -> None:
        """``floor`` (metres, > 0): a configuration is valid only as far as that from the table and obstacles."""

        def many(qs: np.ndarray) -> np.ndarray:
            qs = np.atleast_2d(np.asarray(qs, float))
            ok = ~np.asarray(scene.in_collision(arm, qs), bool)
            if floor > 0.0 and ok.any():
                # upto=floor: the clearance's OBB bounds prune every pair farther than the floor, so this costs
                # little more than the collision check
                ok[ok] = np.asarray(scene.clearance(arm, qs[ok], upto=floor), float) >= floor
            return ok

        self.valid = batched(lambda q: bool(many(np.asarray(q, float)[None, :])[0]), many)
        # T-RRT climbs this cost map: high within a few mm of obstacles, flat beyond 10 cm (metres),
        # so clearances beyond 10 cm need not be measured exactly.
        cap = 0.10
        clearance = batched(
            lambda q: float(scene.clearance(arm, np.asarray(q, float)[None, :], upto=cap)[0]),
            lambda qs: np.asarray(scene.clearance(arm, qs, upto=cap), float),
        )
        self.cost = inverse_clearance_cost(clearance, floor=0.005, cap=cap)


def first_hit(scene: PlanningScene, arm: str, path: np.ndarray, ignore: Sequence[str] = ()) -> int | None:
    """Index of the first configuration of ``path`` ``(n, dof)`` in collision in ``scene``, or ``None``."""
    hits = scene.in_collision(arm, np.asarray(path, float), ignore=ignore)
    return int(np.argmax(hits)) if np.any(hits) else None


def free_motion(
    robot: Robot,
    scene: PlanningScene,
    planner: MotionPlanner,
    arm: str,
    q_a: np.ndarray,
    q_b: np.ndarray,
    settings: AssemblySettings,
    edge: tuple[Any, Any],
    what: str,
    clearances: list[float],
) -> np.ndarray:
    """A collision-free joint path in ``scene`` from the motion planner, cost = inverse clearance, that keeps
    ``settings.transit_clearance`` where its ends allow (:func:`_clearance_floor`); its minimum clearance
    (metres) is appended to ``clearances``."""
    chk = Checker(scene, arm)
    lo, hi = robot.joint_limits(arm)
    q_a, q_b = np.asarray(q_a, float), np.asarray(q_b, float)

    def plan(check: Checker) -> Any:
        return planner.plan(
            q_a, q_b, lower=lo, upper=hi, is_valid=check.valid, cost=check.cost, time_limit=settings.motion_time_limit
        )

    res = plan(chk)
    if not res.success or res.path is None:
        # The goal configuration itself is in collision (a held part against the robot, say): no motion
        # to it can succeed, whatever edge leads there.
        bad_goal = edge[1] if res.kind is FailureKind.GOAL_INVALID else None
        raise MotionFailure(edge, f"{what}: {res.reason}", node=bad_goal, timed_out=res.kind is FailureKind.TIMEOUT)
    path = np.asarray(res.path, float)
    # the free motion's least clearance in the world it was planned in (the statistics, and the floor's test)
    least = float(np.min(scene.clearance(arm, densify(path, CLEARANCE_STEP_RAD))))
    # T-RRT's cost only prefers clearance and its shortcuts may graze what they pass (0.2-1.5 mm seen on the
    # structures' free motions): a path that came closer than the floor is planned again with the floor as a
    # constraint
    floor = _clearance_floor(scene, arm, q_a, q_b, settings.transit_clearance)
    if least < floor:
        kept = plan(Checker(scene, arm, floor=floor))
        if kept.success and kept.path is not None:
            path = np.asarray(kept.path, float)
            least = float(np.min(scene.clearance(arm, densify(path, CLEARANCE_STEP_RAD))))
    clearances.append(least)
    return path


CLEARANCE_STEP_RAD = 0.02
"""Joint step (radians) at which a free motion's clearance is measured: a link 0.7 m out moves ~14 mm a step."""


def _clearance_floor(scene: PlanningScene, arm: str, q_a: np.ndarray, q_b: np.ndarray, wanted: float) -> float:
    """The clearance (metres) a free motion from ``q_a`` to ``q_b`` can be asked to keep: ``wanted``, or less
    where an end has less (a hand about to grasp, a part about to go in), with a little slack so an end is
    itself valid; 0 when ``wanted`` is 0."""
    if wanted <= 0.0:
        return 0.0
    ends = np.asarray(scene.clearance(arm, np.stack([q_a, q_b]), upto=wanted), float)
    return float(min(wanted, 0.9 * float(np.min(ends))))


def straight_line(
    robot: Robot,
    scene: PlanningScene,
    arm: str,
    q_from: np.ndarray,
    T_to: np.ndarray,
    settings: AssemblySettings,
    edge: tuple[Any, Any],
    what: str,
    ignore: Sequence[str] = (),
    node: Any | None = None,
) -> np.ndarray:
    """A straight TCP line, collision-free in ``scene`` but for ``ignore``; on failure ``node``, the grasp at the
    slot the line belongs to, is banned whole."""
    path, why = cartesian_path(robot, arm, np.asarray(q_from, float), T_to, settings.cartesian_step)
    if path is None:
        raise MotionFailure(edge, f"{what}: {why}", node=node)
    hit = first_hit(scene, arm, path, ignore=ignore)
    if hit is not None:
        pairs = scene.collision_report(arm, path[hit])
        who = ", ".join(f"{a}/{b}" for a, b in pairs[:2]) or "unknown pair"
        raise MotionFailure(edge, f"{what}: collision at step {hit} ({who})", node=node)
    return path
