"""The measure stage: the achieved T_A_B against the taught and the true one (mm, deg), and success."""

from __future__ import annotations

from typing import Any

from asmteach.core import geometry
from asmteach.core.failures import FailureCause
from asmteach.core.interfaces import PartModel, Robot
from asmteach.core.io import write_json
from asmteach.core.models import AssemblyTask, RunReport
from asmteach.core.pipeline.stage import Run, StageFailed
from asmteach.core.pose_error import pose_error

__all__ = ["SLIP_NOTE_MM", "measure_stage"]


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
        run.report.success = bool(ok)
        if not ok:
            slip = _worst_slip(run.report)
            raise StageFailed(
                f"assembled outside tolerance: B in A off by {vs_taught.position_mm:.2f} mm / "
                f"{vs_taught.angle_deg:.2f} deg (limits {ex.success_position_mm} mm / {ex.success_angle_deg} deg), "
                f"A {a_goal_mm:.2f} mm from its goal (limit {ex.success_a_goal_mm} mm)" + _slip_note(slip),
                cause=_outside_tolerance_cause(slip),
            )


SLIP_NOTE_MM = 1.0
"""A part this far (mm) from where the hand should hold it at its release was pushed in the hand: the motion
before the release met resistance (a jam on an insertion, a collision); the failure reason names it."""


def _worst_slip(report: RunReport) -> dict[str, Any] | None:
    """The execution trace's release event with the largest slip in the hand beyond :data:`SLIP_NOTE_MM`, else None.

    Its fields (:class:`asmteach.core.pipeline.execute._ExecutionTrace`): ``part``, ``label`` (the release),
    ``after`` / ``after_kind`` (the motion before it and its kind), ``slip_in_hand_mm``.
    """
    events = [
        ev
        for st in report.stages
        if st.stage in ("execute_a", "execute")
        for ev in (st.details or {}).get("trace", [])
        if ev.get("slip_in_hand_mm", 0.0) > SLIP_NOTE_MM
    ]
    return max(events, key=lambda e: e["slip_in_hand_mm"]) if events else None


def _outside_tolerance_cause(slip: dict[str, Any] | None) -> FailureCause:
    """Jam when the worst slip in the hand (:func:`_worst_slip`) came during an insertion motion (the part met
    resistance there), else off goal (pushed elsewhere, e.g. A at its placing, or not pushed at all).

    Toppling has no structured evidence in the trace yet, so :attr:`FailureCause.TOPPLE` is not decided here.
    """
    return FailureCause.JAM if slip is not None and slip.get("after_kind") == "insertion" else FailureCause.OFF_GOAL


def _slip_note(ev: dict[str, Any] | None) -> str:
    """``"; <part> was pushed N mm in the hand by '<motion>' ..."`` for the worst slip event, else ``""``."""
    if ev is None:
        return ""
    return (
        f"; {ev.get('part', 'the part')} was pushed {ev['slip_in_hand_mm']:.1f} mm in the hand by "
        f"{ev.get('after') or ev['label']!r} (it met resistance there: a jam, if that is the insertion)"
    )
