"""The order of the stages: :func:`run_pipeline` runs one config into an output folder."""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

from asmteach.core import registry
from asmteach.core.config import RunConfig
from asmteach.core.errors import UserError
from asmteach.core.interfaces import Robot
from asmteach.core.models import Plan, RunReport
from asmteach.core.pipeline.detect import detect_stage, spawn_stage
from asmteach.core.pipeline.execute import execute_stage, write_animation
from asmteach.core.pipeline.measure import measure_stage
from asmteach.core.pipeline.plan import grasps_stage, look_again_stage, plan_stage
from asmteach.core.pipeline.report import finish_run
from asmteach.core.pipeline.stage import Run, StageFailed
from asmteach.core.pipeline.teach import teach_stage
from asmteach.core.robot import World

__all__ = ["run_pipeline"]


def run_pipeline(cfg: RunConfig, out_dir: Path, *, pm: Any | None = None) -> RunReport:
    """Run the whole pipeline of ``cfg`` into ``out_dir``; the report is returned and written.

    Raises :class:`UserError` only for bad input found before anything runs
    (config, structure file); every later failure is recorded in the report.
    """
    from asmteach.core.run_setup import prepare_run

    setup = prepare_run(cfg)  # every object of the run built and checked before anything is written
    cfg = setup.cfg  # the robot's settings now carry the config's table
    if not issubclass(registry.get_class("robots", cfg.robot.plugin), World):
        raise UserError(
            f"robot.plugin: {cfg.robot.plugin!r} plans but has no world to run in (a robot the run "
            "executes on is also an asmteach.core.robot.World: reset, execute, grip, sense)"
        )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    run = Run(cfg, out, pm)
    true_task = setup.task
    part_a, part_b = setup.part_a, setup.part_b
    robot: Robot | None = None
    try:
        learned = teach_stage(run, true_task)
        robot = run.plugin("robot")
        table = setup.table  # the one table plane of the run (cfg.table.height)
        truth = spawn_stage(run, robot, part_a, part_b, table)
        detections = detect_stage(run, robot, (part_a, part_b), table, truth)
        grasps = grasps_stage(run, robot, part_a, part_b)
        result = plan_stage(run, robot, learned, part_a, part_b, detections, grasps, table)
        plan, frames = result.plan, []
        head = list(itertools.takewhile(lambda seg: seg.part == part_a.name, plan.segments))
        look = run.execution.look_again
        if head and (look == "always" or (look == "ambiguous" and detections[part_a.name].details.get("ambiguous"))):
            frames += execute_stage(run, robot, Plan(segments=head), stage="execute_a")
            result, plan = look_again_stage(
                run,
                robot,
                learned,
                (part_a, part_b),
                detections,
                grasps,
                table,
                result,
                Plan(segments=plan.segments[len(head) :], stats=plan.stats),
            )
        frames += execute_stage(run, robot, plan)
        if frames:
            write_animation(run, frames)
        measure_stage(run, robot, learned, true_task, part_a, part_b, result)
    except StageFailed:
        pass
    finally:
        if robot is not None:
            robot.close()
    finish_run(run)
    return run.report
