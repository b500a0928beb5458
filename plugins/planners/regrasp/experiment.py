"""Experiment ``assembly_planning``: random start placements per structure, the regrasp planner on the Nextage.

One trial: the structure's parts spawned at random stable placements, yaws and
positions (``asmteach.core.scene``, seeded), exact start poses (planning is
measured alone, without detection), the configured motion planner. Recorded:
success and the reason of a failure, seconds per stage (feasibility graph,
keyframe search, motions, total), regrasps per part, joint-path length, plan
duration, the minimum clearance (mm) of the free motions (robot's own collision
model), and the independent re-check of the whole plan (PyBullet contact
queries on the same URDF, every 5 mm of motion: ``recheck_ok``,
``recheck_collisions``, ``recheck_min_distance_mm``).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import Field

from asmteach.core import registry
from asmteach.core.config import SceneSettings, check_plugin_settings
from asmteach.core.interfaces import AssemblyProblem
from asmteach.core.models import StrictModel, TablePlane
from asmteach.core.parts import build_part, load_structure
from asmteach.core.scene import random_start_poses
from asmteach.core.sweep import Experiment

__all__ = ["AssemblyPlanningExperiment"]


class AssemblyPlanningParams(StrictModel):
    structure: str = Field(description="structure YAML, relative to the experiment file")
    motion_planner: str = "trrt"
    motion_settings: dict[str, Any] = Field(default_factory=dict)
    planner_settings: dict[str, Any] = Field(default_factory=dict)
    robot_settings: dict[str, Any] = Field(default_factory=lambda: {"ik": {"max_starts": 4}})
    scene: SceneSettings = Field(default_factory=SceneSettings)
    recheck: bool = Field(True, description="re-check every successful plan with the robot's independent checker")
    recheck_resolution: float = Field(0.005, gt=0.0, description="metres any point may move between re-checks")


class AssemblyPlanningExperiment(Experiment):
    """Success, time per stage, regrasps, path length and clearance of whole two-part plans."""

    Params = AssemblyPlanningParams
    plot_metrics = ("success", "recheck_ok", "seconds", "motion_seconds", "regrasps", "path_length", "min_clearance_mm")

    def check(self, params: AssemblyPlanningParams) -> None:
        """The robot's, motion planner's and assembly planner's settings by their plugins' models, before any trial."""
        for role, name, key in (
            ("robots", "nextage_pybullet", "robot"),
            ("motion_planners", params.motion_planner, "motion"),
            ("assembly_planners", "regrasp", "planner"),
        ):
            check_plugin_settings(
                role,
                name,
                getattr(params, f"{key}_settings"),
                name_key="params.motion_planner",
                settings_key=f"params.{key}_settings",
            )

    def run_trial(self, params: AssemblyPlanningParams, seed: int, workdir: Path) -> dict[str, Any]:
        task = load_structure(self.path(params.structure))
        a, b = build_part(task.part_a), build_part(task.part_b)
        robot = registry.create("robots", "nextage_pybullet", params.robot_settings, seed=seed)
        try:
            grasps = registry.create("grasp_planners", "antipodal", {}, seed=seed)
            motion = registry.create("motion_planners", params.motion_planner, params.motion_settings, seed=seed)
            planner = registry.create("assembly_planners", "regrasp", params.planner_settings, seed=seed)
            T_a, T_b = random_start_poses([a, b], 0.0, params.scene, np.random.default_rng([seed, 11]))
            problem = AssemblyProblem(
                a, b, task, T_a, T_b, grasps.plan(a, robot.hand), grasps.plan(b, robot.hand), TablePlane(height=0.0)
            )
            t0 = time.perf_counter()
            res = planner.plan(problem, robot, motion)
            total = time.perf_counter() - t0
            row: dict[str, Any] = {"success": bool(res.success), "seconds": total, "reason": res.reason or ""}
            stats = res.plan.stats
            for part in ("A", "B"):
                st = stats.get(part) or {}
                for key in ("graph_seconds", "search_seconds", "motion_seconds", "regrasps", "attempts"):
                    if key in st:
                        row[f"{part}_{key}"] = st[key]
            row["motion_seconds"] = sum(row.get(f"{p}_motion_seconds", 0.0) for p in ("A", "B"))
            row["graph_seconds"] = sum(row.get(f"{p}_graph_seconds", 0.0) for p in ("A", "B"))
            row["regrasps"] = sum(row.get(f"{p}_regrasps", 0) for p in ("A", "B"))
            if res.success:
                row["execution_seconds"] = stats.get("execution_seconds")
                row["path_length"] = float(
                    sum(
                        np.linalg.norm(np.diff(np.asarray(s.trajectory.positions), axis=0), axis=1).sum()
                        for s in res.plan.segments
                        if s.trajectory is not None
                    )
                )
                mins = [(stats.get(p) or {}).get("min_clearance_m", np.nan) for p in ("A", "B")]
                row["min_clearance_mm"] = 1000.0 * float(np.nanmin(mins))
                if params.recheck:
                    chk = robot.verify_plan(
                        res.plan,
                        {a.name: (a, T_a), b.name: (b, T_b)},
                        problem.table,
                        resolution=params.recheck_resolution,
                    )
                    row["recheck_ok"] = bool(chk.ok)
                    row["recheck_collisions"] = len(chk.collisions)
                    row["recheck_min_distance_mm"] = 1000.0 * float(chk.min_distance_m)
                    row["recheck_seconds"] = float(chk.seconds)
                    if not chk.ok:
                        row["reason"] = f"re-check: {chk.summary()}"
            return row
        finally:
            robot.close()
