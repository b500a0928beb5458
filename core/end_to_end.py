"""Experiment ``end_to_end``: whole ``asmteach run`` trials over seeds (issue 9's success target).

One trial runs the pipeline of a run config (teach, spawn, detect, correct,
grasp, plan, execute, measure) with the trial's seed, which draws the start
placements, noise and every plugin's random choices. Recorded: success, the
stage that failed and why, the achieved error of B in A against the taught
pose (mm, deg, modulo the parts' symmetries), A's distance to its goal (mm),
and both clocks: the computer's seconds per stage (``<stage>_seconds``) and the
robot's seconds of simulated motion (``robot_seconds``, ``robot_<kind>_seconds``
for transit, approach, insertion, regrasp; ``plan_robot_seconds`` and
``plan_robot_seconds_trapezoid``, the plan's with its timing and with the old
trapezoid on the same paths). Each trial's run directory (report.json/html, plan,
figures) is kept under the sweep's trial work directory.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import Field

from asmteach.core.config import load_run_config
from asmteach.core.models import RunReport, StrictModel
from asmteach.core.sweep import Experiment

__all__ = ["EndToEnd", "report_row", "run_config_trial"]


class EndToEndParams(StrictModel):
    run_config: str = Field(description="run config YAML, relative to the experiment file")
    overrides: dict[str, Any] = Field(
        default_factory=lambda: {"execution.animation": False},
        description="dotted config keys set for every trial (as asmteach run --set)",
    )


class EndToEnd(Experiment):
    """Success rate and achieved assembly error of whole runs."""

    Params = EndToEndParams
    plot_metrics = (
        "success",
        "achieved_vs_taught_mm",
        "achieved_vs_taught_deg",
        "a_goal_error_mm",
        "plan_seconds",
        "robot_seconds",
    )  # six at most: the computer's planning clock, the robot's clock

    def check(self, params: EndToEndParams) -> None:
        """The run config with the overrides, loaded as a trial loads it: a misspelt key fails before any trial."""
        load_run_config(self.path(params.run_config), overrides=params.overrides)

    def run_trial(self, params: EndToEndParams, seed: int, workdir: Path) -> dict[str, Any]:
        _, row = run_config_trial(self.path(params.run_config), params.overrides, seed, workdir)
        return row


def run_config_trial(
    run_config: Path, overrides: dict[str, Any], seed: int, workdir: Path
) -> tuple[RunReport, dict[str, Any]]:
    """Run the whole pipeline of ``run_config`` with ``seed`` into ``workdir/run``; return the report and its row.

    ``overrides``: dotted config keys set before validation (as ``asmteach run --set``); the seed is set last.
    Shared by the experiments that run whole pipelines (``end_to_end``, ``structures_corpus``).
    """
    from asmteach.core.pipeline import run_pipeline

    cfg = load_run_config(run_config, overrides={**overrides, "seed": seed})
    report = run_pipeline(cfg, Path(workdir) / "run")
    return report, report_row(report)


def report_row(report: RunReport) -> dict[str, Any]:
    """A run report as one flat sweep row: outcome (with the failure's cause,
    :class:`~asmteach.core.failures.FailureCause`), errors (mm, deg), computer seconds per stage, robot seconds."""
    row: dict[str, Any] = {
        "success": bool(report.success),
        "failed_stage": report.failed_stage or "",
        "failure_cause": str(report.failure_cause or ""),
        "reason": report.reason or "",
    }
    for key in ("achieved_vs_taught_mm", "achieved_vs_taught_deg", "a_goal_error_mm", "plan_recheck_collisions"):
        if key in report.metrics:
            row[key] = report.metrics[key]
    for stage in report.stages:
        row[f"{stage.stage}_seconds"] = stage.seconds
    # the robot's clock beside the computer's: simulated motion seconds executed, by kind, and the plan's
    # own with the timing used and with the trapezoid on the same paths (issue 27)
    for kind, seconds in report.robot_seconds.items():
        row["robot_seconds" if kind == "total" else f"robot_{kind}_seconds"] = seconds
    for key, name in (
        ("robot_seconds", "plan_robot_seconds"),
        ("robot_seconds_trapezoid", "plan_robot_seconds_trapezoid"),
    ):
        planned = report.plan_stats.get(key)
        if isinstance(planned, dict) and "total" in planned:
            row[name] = planned["total"]
    return row
