"""The measure stage: the achieved T_A_B against the taught and the true one (mm, deg), and success."""

from __future__ import annotations

from typing import Any

from asmteach.core import geometry
from asmteach.core.interfaces import PartModel, Robot
from asmteach.core.io import write_json
from asmteach.core.models import AssemblyTask
from asmteach.core.pipeline.causes import failure_story, insertion_error
from asmteach.core.pipeline.stage import Run, StageFailed
from asmteach.core.pose_error import pose_error

__all__ = ["measure_stage"]


def measure_stage(
    run: Run, robot: Robot, learned: AssemblyTask, true_task: AssemblyTask, a: PartModel, b: PartModel, result: Any
) -> None:
    with run.stage("measure") as d:
        T_a, T_b = robot.part_pose(a.name), robot.part_pose(b.name)
        T_A_B = geometry.invert(T_a) @ T_b
        # A symmetric part may be detected, and so assembled, in any of its symmetric poses.
        sym_a, sym_b = run.symmetries(a), run.symmetries(b)
        vs_taught = pose_error(T_A_B, learned.T_A_B, sym_a, sym_b)
        vs_true = pose_error(T_A_B, true_task.T_A_B, sym_a, sym_b)
        a_goal_mm = pose_error(T_a, result.T_world_a_goal, (), sym_a).position_mm
        ex = run.execution
        ok = (
            vs_taught.position_mm <= ex.success_position_mm
            and vs_taught.angle_deg <= ex.success_angle_deg
            and a_goal_mm <= ex.success_a_goal_mm
        )
        run.report.metrics.update(
            achieved_vs_taught_mm=vs_taught.position_mm,
            achieved_vs_taught_deg=vs_taught.angle_deg,
            achieved_vs_true_mm=vs_true.position_mm,
            achieved_vs_true_deg=vs_true.angle_deg,
            a_goal_error_mm=a_goal_mm,
        )
        d.update({k: round(v, 3) for k, v in run.report.metrics.items() if k.startswith(("achieved", "a_goal"))})
        write_json(
            run.out / "achieved.json",
            {
                "T_world_A": T_a.tolist(),
                "T_world_B": T_b.tolist(),
                "T_A_B": T_A_B.tolist(),
                "T_A_B_taught": learned.T_A_B.tolist(),
                "T_A_B_true": true_task.T_A_B.tolist(),
            },
        )
        split = insertion_error(run.report, learned, true_task, result.T_world_a_goal, sym_a)
        if split is not None:
            d["insertion_error"] = split
        run.report.success = bool(ok)
        if not ok:
            note, cause, evidence = failure_story(run.report, split)
            run.report.failure_details = evidence
            raise StageFailed(
                f"assembled outside tolerance: B in A off by {vs_taught.position_mm:.2f} mm / "
                f"{vs_taught.angle_deg:.2f} deg (limits {ex.success_position_mm} mm / {ex.success_angle_deg} deg), "
                f"A {a_goal_mm:.2f} mm from its goal (limit {ex.success_a_goal_mm} mm); " + note,
                details={"failure": evidence},
                cause=cause,
            )
