"""The execute stage: the plan's segments run on the robot's world.

What happened to the parts is traced (mm, deg), the robot's clock counted (simulated seconds) and the
animation (execution.gif) written.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from asmteach.core import geometry
from asmteach.core.failures import FailureCause
from asmteach.core.interfaces import Robot
from asmteach.core.models import Plan, RunReport
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
        trace = _ExecutionTrace(robot)
        d["trace"] = trace.events
        for seg in plan.segments:
            if seg.trajectory is not None:
                for chunk in _chunks(seg.trajectory, period if record else None):
                    robot.execute(chunk)
                    if record:
                        frames.append(robot.sense_rgb())
                trace.after_path(seg.trajectory, seg.label, seg.kind)
                _count_robot_seconds(run.report, seg)
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


def _count_robot_seconds(report: RunReport, seg: Any) -> None:
    """Add an executed motion's duration (simulated seconds) to the report's robot clock, in total and by kind."""
    seconds = float(seg.trajectory.times[-1] - seg.trajectory.times[0])
    clock = report.robot_seconds
    clock["total"] = round(clock.get("total", 0.0) + seconds, 3)
    kind = seg.kind or "unlabelled"
    clock[kind] = round(clock.get(kind, 0.0) + seconds, 3)


class _ExecutionTrace:
    """What happened to the parts during execution, against what the plan assumed.

    One event per gripper action: the part's pose (mm, deg); on close, how far
    it moved since its release (toppled, pushed); on release, how far it
    slipped in the hand while held, the label and kind (``after_kind``:
    transit, approach, insertion, regrasp or None) of the motion before, and
    how far it dropped when let go (mm).
    """

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self.events: list[dict[str, Any]] = []
        self.held: dict[str, str] = {}  # arm -> part
        self.T_tcp_part: dict[str, np.ndarray] = {}  # part -> its pose in the hand at the close
        self.T_released: dict[str, np.ndarray] = {}  # part -> T_world_part after its last release
        self.max_tracking_error = 0.0
        self.last_path: dict[str, str] = {}  # arm -> label of its last motion
        self.last_kind: dict[str, str | None] = {}  # arm -> kind of its last motion (PlanSegment.kind)

    def _tcp(self, arm: str) -> np.ndarray:
        return self.robot.fk(arm, self.robot.current(arm))

    def after_path(self, traj: Any, label: str, kind: str | None = None) -> None:
        err = float(np.max(np.abs(self.robot.current(traj.arm) - np.asarray(traj.positions)[-1])))
        self.max_tracking_error = max(self.max_tracking_error, err)
        self.last_path[traj.arm] = label
        self.last_kind[traj.arm] = kind

    def before_grip(self, label: str, arm: str, close: bool, part: str | None) -> None:
        part = part if close else self.held.get(arm)
        ev: dict[str, Any] = {"label": label}
        if part is not None:
            T = self.robot.part_pose(part)
            ev.update(part=part, **geometry.to_xyz_mm_rpy_deg(T))
            if close and part in self.T_released:
                moved = geometry.translation_distance(T, self.T_released[part])
                ev["moved_since_release_mm"] = round(1000.0 * moved, 2)
            if not close and part in self.T_tcp_part:
                T_expected = self._tcp(arm) @ self.T_tcp_part[part]
                ev["slip_in_hand_mm"] = round(1000.0 * geometry.translation_distance(T, T_expected), 2)
                ev["after"] = self.last_path.get(arm, "")
                ev["after_kind"] = self.last_kind.get(arm)
        self.events.append(ev)

    def after_grip(self, arm: str, close: bool, part: str | None) -> None:
        if close and part is not None:
            self.held[arm] = part
            self.T_tcp_part[part] = geometry.invert(self._tcp(arm)) @ self.robot.part_pose(part)
            return
        part = self.held.pop(arm, None)
        if part is not None:
            T = self.robot.part_pose(part)
            before = self.events[-1]
            moved = np.subtract(T[:3, 3] * 1000.0, before.get("xyz_mm", T[:3, 3] * 1000.0))
            before["dropped_mm"] = round(float(np.linalg.norm(moved)), 2)
            self.T_released[part] = T


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
    images = [Image.fromarray(np.asarray(f, dtype=np.uint8)) for f in frames]
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
