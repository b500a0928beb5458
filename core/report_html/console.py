"""The run report as a console summary: at most 25 plain-text lines of at most 100 characters."""

from __future__ import annotations

from asmteach.core.models import RunReport
from asmteach.core.report_html.facts import (
    ROBOT_KINDS,
    format_value,
    pose_text,
    recorded_errors,
    robot_clock,
    true_pose,
)

SUMMARY_MAX_LINES = 25
_WIDTH = 100  # console summary line width


def _cut(line: str) -> str:
    line = line.replace("\r", " ").replace("\n", " ")  # a multi-line reason must stay one line
    return line if len(line) <= _WIDTH else line[: _WIDTH - 1] + "…"


def format_summary(report: RunReport) -> str:
    """A one-screen plain-text summary (at most 25 lines of at most 100 characters)."""
    name = report.config.get("name") or "run"
    if report.success:
        lines = [f"{name} (seed {report.seed}): SUCCESS"]
    else:
        lines = [f"{name} (seed {report.seed}): FAILED at {report.failed_stage or '?'}"]
        cause = f" ({report.failure_cause.value})" if report.failure_cause is not None else ""
        lines.append(f"  reason{cause}: {report.reason or 'not recorded'}")
    # a plan that relies on a jig says so (asmteach.core.arm.fixture)
    lines += [f"  jig: {s.details['jig']}" for s in report.stages if s.details.get("jig")]
    if report.stages:
        lines.append("stages:")
        stages = report.stages[:8]
        for s in stages:
            status = "ok" if s.ok else "FAILED"
            tail = f"  {s.reason}" if s.reason else ""
            lines.append(f"  {s.stage:<14} {status:<6} {s.seconds:8.2f} s{tail}")
        if len(report.stages) > len(stages):
            lines.append(f"  ... {len(report.stages) - len(stages)} more stages")
    robot = robot_clock(report)
    if robot.get("total") is not None:
        split = ", ".join(f"{k} {robot[k]:.1f}" for k in ROBOT_KINDS if robot.get(k))
        lines.append(
            f"clocks: robot {robot['total']:.1f} s of motion, computer "
            f"{sum(s.seconds for s in report.stages):.1f} s (robot: {split})"
        )
    if report.task is not None:
        xyz, rpy = pose_text(report.task.T_A_B)
        lines.append(f"task {report.task.name}: T_A_B [{xyz}] mm  [{rpy}] deg")
    if report.detections:
        lines.append("detections:")
        for det in report.detections[:4]:
            T = det.best
            if not det.found or T is None:
                lines.append(f"  {det.part}: not found ({det.reason or 'no reason recorded'})")
                continue
            xyz, _ = pose_text(T)
            T_true = true_pose(det)
            err = ""
            if T_true is not None:
                e = recorded_errors(det, "corrected" if det.corrected is not None else "rough", T, T_true)
                err = f"  error {e['position_mm']:.2f} mm / {e['angle_deg']:.2f} deg"
            lines.append(f"  {det.part}: [{xyz}] mm{err}")
    if report.metrics:
        lines.append("metrics:")
        items = [f"{k} = {format_value(v)}" for k, v in report.metrics.items()]
        # Two per line keeps long metric lists on the screen.
        for i in range(0, min(len(items), 12), 2):
            lines.append("  " + "    ".join(items[i : i + 2]))
        if len(items) > 12:
            lines.append(f"  ... {len(items) - 12} more in report.json")
    if report.artefacts:
        lines.append("files: " + ", ".join(report.artefacts.values()))
    lines = [_cut(ln) for ln in lines]
    if len(lines) > SUMMARY_MAX_LINES:
        lines = [*lines[: SUMMARY_MAX_LINES - 1], f"... {len(lines) - SUMMARY_MAX_LINES + 1} more lines"]
    return "\n".join(lines)
