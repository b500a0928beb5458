"""Assembly planner plugin ``regrasp``: A to its goal, then B into A.

Part A is picked at its start pose, regrasped through intermediate stable
placements if needed, and put down at its goal placement: of A's placements
ranked by :mod:`asmteach.plugins.planners.regrasp.goals` (B held in A
under gravity first, then B going in from above), the first at which at least ``min_goal_grasps`` of B's grasps
are feasible when B is assembled (a slider whose only exposed part, standing
up, is a rib beside A's face is easier to hold when A lies flat and B slides
in sideways).
Part B is picked, carried to the pre-assembly pose (retracted along ``-v_a``)
and inserted along ``v_a`` in a straight line; only then is it released.
A symmetric B (a square peg turned by 90 deg about its axis is the same
solid in the same place) has as many assembled poses as its symmetry group
(:func:`asmteach.core.symmetry.part_symmetries`, at most ``goal_symmetries``):
each is a goal slot, and a grasp of B need only be feasible at one of them.
While A moves, B is an obstacle where it lies; while B moves, A is one at its
goal.

Planning starts from the robot's planning scene (:attr:`Robot.scene`: where
the arms are) and checks collisions on scene values made from it; it never
changes the robot.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from asmteach.core.interfaces import (
    AssemblyPlanner,
    AssemblyProblem,
    AssemblyResult,
    MotionPlanner,
    Obstacle,
    PartModel,
    Robot,
)
from asmteach.core.models import Plan
from asmteach.core.rests.insertion_load import seat_friction_n
from asmteach.core.rests.placements import compute_placements
from asmteach.core.robot import PlanningScene
from asmteach.core.symmetry import part_symmetries
from asmteach.plugins.planners.regrasp.assembly import TransferResult, feasible_grasps_at, plan_transfer
from asmteach.plugins.planners.regrasp.goals import (
    AssemblyGoal,
    a_under_insertion,
    assembly_goal_at,
    ranked_assembly_goals,
)
from asmteach.plugins.planners.regrasp.graph import PoseSlot
from asmteach.plugins.planners.regrasp.plan_io import render_regrasp_graph, table_obstacle, to_plan
from asmteach.plugins.planners.regrasp.realise import PlaceGoal
from asmteach.plugins.planners.regrasp.settings import AssemblySettings
from asmteach.plugins.planners.regrasp.slots import placement_slots

__all__ = ["RegraspAssemblyPlanner"]


class RegraspAssemblyPlanner(AssemblyPlanner):
    """Three-layer regrasp graph per part, keyframe motions from the configured motion planner."""

    Settings = AssemblySettings
    settings: AssemblySettings
    _symmetries: dict[str, list[np.ndarray]] | None = None

    def _equivalents(self, part: PartModel) -> list[np.ndarray]:
        """Up to ``goal_symmetries`` of ``part``'s symmetry transforms (part frame), the identity first, spread
        evenly over its group; computed once per part."""
        if self._symmetries is None:
            self._symmetries = {}
        key = part.source_hash or part.name
        if key not in self._symmetries:
            group = part_symmetries(part.mesh, np.asarray(part.center_of_mass, float))
            step = -(-len(group) // self.settings.goal_symmetries)  # ceil: every step-th, the identity first
            self._symmetries[key] = group[::step][: self.settings.goal_symmetries]
        return self._symmetries[key]

    def _goal_slots(self, part: PartModel, T_world_part: np.ndarray) -> tuple[PoseSlot, tuple[PoseSlot, ...]]:
        """B's assembled pose as the goal slot ``assembled``, and its symmetric equivalents ``assembled_sym{k}``."""
        T = np.asarray(T_world_part, float)
        slots = [
            PoseSlot("assembled" if k == 0 else f"assembled_sym{k}", "goal", T @ S)
            for k, S in enumerate(self._equivalents(part))
        ]
        return slots[0], tuple(slots[1:])

    def plan(
        self,
        problem: AssemblyProblem,
        robot: Robot,
        motion_planner: MotionPlanner,
        *,
        scene: PlanningScene | None = None,
        progress: Callable[[str], None] | None = None,
    ) -> AssemblyResult:
        s = self.settings
        t0 = time.perf_counter()
        a, b, h = problem.part_a, problem.part_b, problem.table.height
        scene = robot.scene if scene is None else scene
        table = table_obstacle(scene, h)
        goal, goal_grasps = self._choose_goal(problem, robot, scene, table, progress)
        q_home = {arm: robot.home(arm) for arm in robot.arms}
        details: dict = {
            "goal_placement_a": goal.placement_id,
            "v_world": goal.v_world.tolist(),
            "goal_grasps_b": goal_grasps,
            "goal_holds_b": goal.held,  # False: B would slide out of A there (no goal holding it has grasps)
            "a_under_insertion": _a_load(a, b, goal),
        }
        if progress and not details["a_under_insertion"]["holds"]:
            progress(f"{a.name} at its goal {details['a_under_insertion']['summary']}: it needs holding")
        result = AssemblyResult(
            False, Plan(), T_world_a_goal=goal.T_world_a, T_world_b_goal=goal.T_world_b, details=details
        )

        # Part A: B lies where it was detected and is in the way.
        world_a = [table, Obstacle(b.name, b.mesh, problem.T_world_b)]
        start_a = problem.T_world_a[:3, 3]
        res_a = plan_transfer(
            robot,
            scene,
            motion_planner,
            a,
            problem.grasps_a,
            T_start=problem.T_world_a,
            goal=PlaceGoal(PoseSlot("goal", "goal", goal.T_world_a), np.array([0.0, 0.0, s.lift])),
            middle_slots=lambda every: placement_slots(
                compute_placements(a),
                start_a[:2],
                h,
                s,
                every=every,
                first=(problem.T_world_a[:3, :3], goal.T_world_a[:3, :3]),
            ),
            world=world_a,
            q_now=q_home,
            settings=s,
            progress=progress,
        )
        details["a"] = res_a
        if not res_a.success:
            return self._fail(result, res_a, f"part A ({a.name})", t0, robot)
        assert res_a.scene is not None  # plan_transfer always says where it ended
        res_b = self._plan_b(problem, goal, robot, res_a.scene, motion_planner, res_a.q_end, progress)
        details["b"] = res_b
        if not res_b.success:
            result.plan = self._timed(robot, [("A", a.name, res_a)], t0)
            return self._fail(result, res_b, f"part B ({b.name})", t0, robot, keep_plan=True)
        result.plan = self._timed(robot, [("A", a.name, res_a), ("B", b.name, res_b)], t0)
        result.plan.stats["a_under_insertion"] = details["a_under_insertion"]
        result.success, result.scene = True, res_b.scene
        return result

    def _choose_goal(
        self,
        problem: AssemblyProblem,
        robot: Robot,
        scene: PlanningScene,
        table: Obstacle,
        progress: Callable[[str], None] | None,
    ) -> tuple[AssemblyGoal, int]:
        """A's goal: the best ranked at which ``min_goal_grasps`` of B's grasps are feasible when assembled (else
        the one with the most; checked in ``scene`` with the arms where it has them), and that number."""
        s, a, b, h = self.settings, problem.part_a, problem.part_b, problem.table.height
        goals = ranked_assembly_goals(
            a,
            b,
            problem.task,
            compute_placements(a),
            xy=s.goal_xy,
            yaw=s.goal_yaw,
            table_height=h,
            retract=s.retract,
            vertical_snap=float(np.radians(s.vertical_snap_deg)),
        )
        if s.min_goal_grasps == 0:
            return goals[0], -1
        best: tuple[AssemblyGoal, int] | None = None
        for goal in goals:
            n = 0
            first, others = self._goal_slots(b, goal.T_world_b)
            for slot in (first, *others):  # the equivalents only while too few are feasible
                n += len(
                    feasible_grasps_at(
                        robot,
                        scene,
                        b,
                        problem.grasps_b,
                        slot.T_world_part,
                        [table, Obstacle(a.name, a.mesh, goal.T_world_a)],
                        s,
                    )
                )
                if n >= s.min_goal_grasps:
                    break
            if best is None or n > best[1]:
                best = (goal, n)
            if n >= s.min_goal_grasps:
                break
        assert best is not None  # ranked_assembly_goals raises rather than return none
        if progress and best[0] is not goals[0]:
            progress(
                f"{a.name}: goal placement {best[0].placement_id}, not {goals[0].placement_id} (insertion "
                f"{np.degrees(np.arccos(np.clip(-best[0].v_world[2], -1, 1))):.0f} deg from vertical): "
                f"{best[1]} grasps of {b.name} are feasible when assembled there"
            )
        return best

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
        """B's segments only, into A standing at ``T_world_a`` (seen there); the arms start where ``scene``
        (default the robot's: where the world's arms are after a run's executed segments) has them."""
        s = self.settings
        t0 = time.perf_counter()
        goal = assembly_goal_at(
            problem.part_a,
            problem.part_b,
            problem.task,
            T_world_a,
            -1,
            retract=s.retract,
            vertical_snap=float(np.radians(s.vertical_snap_deg)),
        )
        result = AssemblyResult(
            False,
            Plan(),
            T_world_a_goal=goal.T_world_a,
            T_world_b_goal=goal.T_world_b,
            details={
                "v_world": goal.v_world.tolist(),
                "a_under_insertion": _a_load(problem.part_a, problem.part_b, goal),
            },
        )
        scene = robot.scene if scene is None else scene
        q_now = {arm: np.array(scene.configuration[arm], dtype=float) for arm in robot.arms}
        res_b = self._plan_b(problem, goal, robot, scene, motion_planner, q_now, progress)
        result.details["b"] = res_b
        if not res_b.success:
            return self._fail(result, res_b, f"part B ({problem.part_b.name})", t0, robot)
        result.plan = self._timed(robot, [("B", problem.part_b.name, res_b)], t0)
        result.plan.stats["a_under_insertion"] = result.details["a_under_insertion"]
        result.success, result.scene = True, res_b.scene
        return result

    def _plan_b(
        self,
        problem: AssemblyProblem,
        goal: AssemblyGoal,
        robot: Robot,
        scene: PlanningScene,
        motion_planner: MotionPlanner,
        q_now: dict[str, np.ndarray],
        progress: Callable[[str], None] | None,
    ) -> TransferResult:
        """B from where it lies to the assembled pose, planned from ``scene``; A stands at its goal, B may touch it
        (and the table) only on the insertion."""
        s, a, b, h = self.settings, problem.part_a, problem.part_b, problem.table.height
        world_b = [table_obstacle(scene, h), Obstacle(a.name, a.mesh, goal.T_world_a)]
        start_b = problem.T_world_b[:3, 3]
        back = goal.T_world_b_pre[:3, 3] - goal.T_world_b[:3, 3]  # the retraction, along -v_world
        assembled, equivalents = self._goal_slots(b, goal.T_world_b)
        return plan_transfer(
            robot,
            scene,
            motion_planner,
            b,
            problem.grasps_b,
            T_start=problem.T_world_b,
            goal=PlaceGoal(assembled, back, touch=(a.name, "table"), on_table=False, alternatives=equivalents),
            middle_slots=lambda every: placement_slots(
                compute_placements(b),
                start_b[:2],
                h,
                s,
                every=every,
                first=(problem.T_world_b[:3, :3], goal.T_world_b[:3, :3]),
            ),
            world=world_b,
            q_now=q_now,
            settings=s,
            progress=progress,
        )

    def _timed(self, robot: Robot, parts: list[tuple[str, str, TransferResult]], t0: float) -> Plan:
        """One timed plan of the parts' steps in order; ``parts``: (role "A"/"B", part name, its transfer)."""
        steps, keyframes, owner = [], [], []
        stats: dict = {"A": None, "B": None}
        for key, name, res in parts:
            steps += res.steps
            owner += [name] * len(res.steps)
            keyframes += [dict(k, part=key) for k in res.keyframes]
            stats[key] = res.stats
        stats["planning_seconds"] = round(time.perf_counter() - t0, 3)
        plan = to_plan(
            steps,
            robot,
            self.settings.acceleration,
            keyframes=keyframes,
            stats=stats,
            timing=self.settings.timing,
            insertion_speed=self.settings.insertion_speed,
        )
        for seg, name in zip(plan.segments, owner, strict=True):  # one segment per step
            seg.part = name
        return plan

    def _fail(
        self, result: AssemblyResult, res: TransferResult, who: str, t0: float, robot: Robot, keep_plan: bool = False
    ) -> AssemblyResult:
        result.reason = f"{who}: {res.reason}"
        result.failed_at = who
        result.cause = res.cause
        if not keep_plan:
            result.plan = Plan(stats={"planning_seconds": round(time.perf_counter() - t0, 3)})
        result.details["why_layers"] = res.layers
        return result

    def write_figures(self, result: AssemblyResult, out_dir: Path) -> dict[str, Path]:
        """``regrasp_graph_A.png`` / ``_B.png``: each part's graph with the chosen keyframes highlighted."""
        out: dict[str, Path] = {}
        for key in ("a", "b"):
            res = result.details.get(key)
            if isinstance(res, TransferResult) and res.graph is not None:
                path = Path(out_dir) / f"regrasp_graph_{key.upper()}.png"
                out[f"regrasp_graph_{key.upper()}"] = render_regrasp_graph(
                    res.graph,
                    res.search.nodes if res.search is not None and res.search.success else [],
                    path,
                    title=f"regrasp graph of part {key.upper()}",
                )
        return out


def _a_load(a: PartModel, b: PartModel, goal: AssemblyGoal) -> dict:
    """What B's insertion does to A at ``goal`` (plan stats, report): :func:`a_under_insertion` at the guarded
    insertion's force limit, with A's name, a one-line summary and B's seat friction (newtons)."""
    load = goal.a_load if goal.a_load is not None else a_under_insertion(a, b, goal)
    return {
        "part": a.name,
        **load.as_dict(),
        "seat_friction_n": round(seat_friction_n(b.mass), 3),
        "summary": load.summary(),
    }
