"""The execute stage: the plan's segments run on the robot's world.

What happened to the parts is traced (mm, deg), the robot's clock counted (simulated seconds) and the
animation (execution.gif) written.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from asmteach.core.arm.fixture import clamp_part, jig_decision
from asmteach.core.arm.insertion import guarded_insert
from asmteach.core.failures import FailureCause
from asmteach.core.interfaces import Robot
from asmteach.core.models import Plan, RunReport
from asmteach.core.pipeline.causes import jam_note
from asmteach.core.pipeline.monitor import ExecutionTrace, plan_parts
from asmteach.core.pipeline.stage import Run, StageFailed

__all__ = ["execute_stage", "write_animation"]


def execute_stage(run: Run, robot: Robot, plan: Plan, stage: str = "execute") -> list[np.ndarray]:
    frames: list[np.ndarray] = []
    with run.stage(stage, total=len(plan.segments)) as d:
        record = run.execution.animation
        period = 1.0 / run.execution.animation_fps
        if record:
            try:
                frames.append(robot.sense_rgb())
            except NotImplementedError:  # World.sense_rgb is optional: no colour camera, no animation
                record = False
                d["animation"] = f"not recorded: {type(robot).__name__} has no colour camera"
        task = run.report.task  # the plan may move B alone (after look_again): A is watched all the same
        parts = plan_parts(plan) + ([task.part_a.name, task.part_b.name] if task is not None else [])
        trace = ExecutionTrace(robot, list(dict.fromkeys(parts)), run.report.robot_seconds.get("total", 0.0))
        d["trace"] = trace.events
        jig = _jig(run, plan, d)
        for seg in plan.segments:
            if seg.trajectory is not None:
                if jig is not None and seg.kind == "insertion":  # A is at its goal now: clamp it where it stands
                    d["jig_clamped"] = clamp_part(robot, jig)
                trace.before_path()
                seconds = _insert(robot, seg, trace, run.report) if seg.kind == "insertion" else None
                if seconds is None:
                    for chunk in _chunks(seg.trajectory, period if record else None):
                        robot.execute(chunk)
                        if record:
                            frames.append(robot.sense_rgb())
                elif record:
                    frames.append(robot.sense_rgb())
                trace.after_path(seg.trajectory, seg.label, seg.kind, seconds)
                _count_robot_seconds(run.report, seg, seconds)
            elif seg.gripper is not None:
                ev = seg.gripper
                close = ev.action == "close"
                trace.before_grip(seg.label, ev.arm, close, ev.attach)
                ok = robot.grip(ev.arm, close, ev.attach)
                if close and not ok:
                    raise StageFailed(
                        f"{seg.label}: the fingers did not close on the part", cause=FailureCause.EXECUTION_DROP
                    )
                trace.after_grip(ev.arm, close, ev.attach)
            run.hook("asmteach_stage_progress", stage="execute", advance=1, message=seg.label)
        d["segments"] = len(plan.segments)
        d["frames_recorded"] = len(frames)
        d["max_tracking_error_rad"] = trace.max_tracking_error
    return frames


def _jig(run: Run, plan: Plan, d: dict) -> str | None:
    """The part a jig holds during this plan's insertions (:mod:`asmteach.core.arm.fixture`), or None; the
    decision's note goes in the stage's details and the report's metrics say whether A was held."""
    task = run.report.task
    if task is None or not any(seg.kind == "insertion" for seg in plan.segments):
        return None
    decision = jig_decision(run.execution.fixture, task.part_a.name, plan.stats.get("a_under_insertion"))
    if decision.note:
        d["jig"] = decision.note
    run.report.metrics["a_held_by_jig"] = float(decision.hold)
    return task.part_a.name if decision.hold else None


def _insert(robot: Robot, seg: Any, trace: ExecutionTrace, report: RunReport) -> float | None:
    """Run an insertion guarded (:func:`~asmteach.core.arm.insertion.guarded_insert`) when its arm holds a part;
    the robot seconds it took, or None when the arm holds nothing (it runs as planned). An insertion that
    stops short fails the stage as a jam (depth, force, time)."""
    arm = seg.trajectory.arm
    part = trace.held.get(arm)
    if part is None:
        return None
    other = trace.other_part(part)
    q = np.asarray(seg.trajectory.positions)
    outcome = guarded_insert(robot, seg.trajectory, part, other)
    trace.insertion(seg.label, part, other, outcome, robot.fk(arm, q[0]), robot.fk(arm, q[-1]))
    if not outcome.inserted:
        # the plan goes on from the end of the insertion: the arm is not there, and the part is not in
        ev = {k: v for k, v in trace.events[-1].items() if not k.startswith("T_")}
        report.failure_details = {"event": ev}
        raise StageFailed(jam_note(ev), details={"failure": {"event": ev}}, cause=FailureCause.JAM)
    return outcome.seconds


def _count_robot_seconds(report: RunReport, seg: Any, seconds: float | None = None) -> None:
    """Add an executed motion's duration (simulated seconds; default: its trajectory's) to the report's robot
    clock, in total and by kind."""
    if seconds is None:
        seconds = float(seg.trajectory.times[-1] - seg.trajectory.times[0])
    clock = report.robot_seconds
    clock["total"] = round(clock.get("total", 0.0) + seconds, 3)
    kind = seg.kind or "unlabelled"
    clock[kind] = round(clock.get(kind, 0.0) + seconds, 3)


def _chunks(traj: Any, period: float | None) -> list[Any]:
    """Split a trajectory into pieces of about ``period`` seconds (for animation frames)."""
    if period is None or traj.times[-1] <= period:
        return [traj]
    times = np.asarray(traj.times)
    cuts = [0]
    next_t = period
    for i, t in enumerate(times):
        if t >= next_t:
            cuts.append(i)
            next_t = t + period
    if cuts[-1] != len(times) - 1:
        cuts.append(len(times) - 1)
    out = []
    for i0, i1 in itertools.pairwise(cuts):
        if i1 <= i0:
            continue
        t = times[i0 : i1 + 1] - times[i0]
        out.append(
            type(traj)(
                arm=traj.arm,
                joint_names=traj.joint_names,
                times=t.tolist(),
                positions=np.asarray(traj.positions)[i0 : i1 + 1],
            )
        )
    return out


def write_animation(run: Run, frames: list[np.ndarray]) -> None:
    from PIL import Image

    from asmteach.core.io import atomic_path

    path = run.out / "execution.gif"
    rgb = [np.asarray(f, dtype=np.uint8) for f in frames]
    # One 256-colour palette for the whole GIF, from a few frames spread over it (the scene's colours do not
    # change, only where they are), and each frame mapped onto it without dithering: PIL's default quantises
    # every RGB frame on its own with median cut, 15-40 ms a 640 x 480 frame, most of the GIF's writing time.
    sample = np.concatenate([rgb[k] for k in np.linspace(0, len(rgb) - 1, min(4, len(rgb))).astype(int)])
    palette = Image.fromarray(sample).quantize(256, method=Image.Quantize.FASTOCTREE)
    images = [Image.fromarray(f).quantize(palette=palette, dither=Image.Dither.NONE) for f in rgb]
    with atomic_path(path) as tmp:
        images[0].save(
            tmp,
            format="GIF",
            save_all=True,
            append_images=images[1:],
            duration=int(1000 / run.execution.animation_fps),
            loop=0,
        )
    run.artefact("animation", path, "gif")
