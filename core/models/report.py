"""What a run records: each stage's outcome and the run report (``report.json``)."""

from __future__ import annotations

from typing import Any

from pydantic import Field

from asmteach.core.failures import FailureCause
from asmteach.core.models.base import StrictModel
from asmteach.core.models.detection import Detection
from asmteach.core.models.task import AssemblyTask

__all__ = ["RunReport", "StageOutcome"]


class StageOutcome(StrictModel):
    """How one pipeline stage ended."""

    stage: str
    ok: bool
    seconds: float = 0.0
    reason: str | None = None
    details: dict[str, Any] = Field(default_factory=dict)


class RunReport(StrictModel):
    """Everything ``asmteach run`` measured, written as ``report.json``."""

    config: dict[str, Any]
    seed: int
    success: bool = False
    failed_stage: str | None = None
    reason: str | None = None
    failure_cause: FailureCause | None = Field(
        None,
        description="why the run failed, as a kind to count and branch on (asmteach.core.failures.FailureCause: "
        "teach, detect_not_found, detect_ambiguous, correct, no_grasp, regrasp_graph, motion, execution_drop, jam, "
        "topple, off_goal, other); decided by the failing stage from structured data, never parsed from the reason; "
        "None on success and in reports written before it existed",
    )
    failure_details: dict[str, Any] = Field(
        default_factory=dict,
        description="the evidence the failing stage named its cause from (measure: the execution event - the "
        "jammed insertion's depth, contact force and time, the part that toppled or was moved and by which motion "
        "and when - and the insertion's error split into grasp, A's placement and taught pose, mm / deg); empty "
        "on success and where the stage records none",
    )
    stages: list[StageOutcome] = Field(default_factory=list)
    task: AssemblyTask | None = None
    detections: list[Detection] = Field(default_factory=list)
    plan_stats: dict[str, Any] = Field(default_factory=dict)
    metrics: dict[str, float] = Field(default_factory=dict)
    robot_seconds: dict[str, float] = Field(
        default_factory=dict,
        description="the robot's clock: seconds of simulated motion executed, total and per kind (transit, "
        "approach, insertion, regrasp); empty when nothing was executed (the plan's own are in plan_stats)",
    )
    computer_seconds: dict[str, float] = Field(
        default_factory=dict, description="the computer's clock: wall seconds per stage, and their total"
    )
    artefacts: dict[str, str] = Field(default_factory=dict)
