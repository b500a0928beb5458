"""Both clocks in report.json, report.html, the console summary and the end_to_end sweep's rows (issue 27)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from asmteach.core import pipeline
from asmteach.core.end_to_end import EndToEnd
from asmteach.core.models import PlanSegment, RunReport, StageOutcome, Trajectory
from asmteach.core.pipeline import execute as pipeline_execute
from asmteach.core.report_html import format_summary, render_report_html

ROOT = Path(__file__).resolve().parents[2]

PLAN_STATS = {
    "timing": "toppra",
    "robot_seconds": {"total": 50.0, "transit": 20.0, "approach": 5.0, "insertion": 2.0, "regrasp": 23.0},
    "robot_seconds_trapezoid": {"total": 120.0, "transit": 30.0, "approach": 22.0, "insertion": 2.3, "regrasp": 65.7},
}


def _report(**kw) -> RunReport:
    fields = dict(
        config={"name": "clocks"},
        seed=4,
        success=True,
        stages=[
            StageOutcome(stage="plan", ok=True, seconds=30.5),
            StageOutcome(stage="execute", ok=True, seconds=40.25),
        ],
        plan_stats=PLAN_STATS,
        robot_seconds={"total": 49.5, "transit": 20.0, "approach": 5.0, "insertion": 2.0, "regrasp": 22.5},
        computer_seconds={"plan": 30.5, "execute": 40.25, "total": 70.75},
    )
    fields.update(kw)
    return RunReport(**fields)


def test_executed_segments_add_to_the_robot_clock_by_kind() -> None:
    report = RunReport(config={}, seed=0)
    traj = Trajectory(arm="left", joint_names=["j"], times=[0.0, 0.5, 1.25], positions=np.zeros((3, 1)))
    pipeline_execute._count_robot_seconds(report, PlanSegment(label="carry", trajectory=traj, kind="transit"))
    pipeline_execute._count_robot_seconds(report, PlanSegment(label="insert", trajectory=traj, kind="insertion"))
    pipeline_execute._count_robot_seconds(report, PlanSegment(label="x", trajectory=traj))
    assert report.robot_seconds == {"total": 3.75, "transit": 1.25, "insertion": 1.25, "unlabelled": 1.25}
    back = RunReport.model_validate_json(report.model_dump_json())
    assert back.robot_seconds == report.robot_seconds


def test_html_and_summary_show_both_clocks() -> None:
    html = render_report_html(_report(), Path("."))
    assert "<h2>Clocks</h2>" in html and "Robot (simulated motion)" in html and "Computer (wall time)" in html
    for text in ("49.5", "50", "120", "70.75", "regrasp", "insertion", "trapezoid"):
        assert text in html
    assert "robot 49.50 s of motion" in html
    summary = format_summary(_report())
    assert "clocks: robot 49.5 s of motion" in summary and "computer 70.8 s" in summary
    # a run that never executed shows the plan's robot seconds
    html = render_report_html(_report(robot_seconds={}), Path("."))
    assert "robot 50.00 s of motion" in html


def test_end_to_end_rows_carry_both_clocks(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "run.yaml").write_text(
        yaml.safe_dump({"name": "t", "seed": 1, "structure": str(ROOT / "configs/parts/set1/peg_in_hole.yaml")})
    )
    monkeypatch.setattr(pipeline, "run_pipeline", lambda cfg, out_dir, pm=None: _report())
    exp = EndToEnd(tmp_path)
    row = exp.run_trial(exp.Params(run_config="run.yaml"), 3, tmp_path / "trial")
    assert row["robot_seconds"] == 49.5 and row["robot_regrasp_seconds"] == 22.5
    assert row["robot_insertion_seconds"] == 2.0
    assert row["plan_robot_seconds"] == 50.0 and row["plan_robot_seconds_trapezoid"] == 120.0
    assert row["plan_seconds"] == 30.5 and row["execute_seconds"] == 40.25
