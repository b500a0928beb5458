"""A run whose A was held by a jig says so in the HTML report's header and the console summary."""

from __future__ import annotations

from pathlib import Path

from asmteach.core.models import RunReport, StageOutcome
from asmteach.core.report_html.console import format_summary
from asmteach.core.report_html.page import render_report_html

NOTE = "block held by a jig during the insertion: at its goal it slides under 20.0 N"


def _report(details: dict) -> RunReport:
    return RunReport(
        config={"name": "slide"}, seed=7, success=True, stages=[StageOutcome(stage="execute", ok=True, details=details)]
    )


def test_the_jig_is_said_in_both_reports(tmp_path: Path) -> None:
    report = _report({"jig": NOTE, "jig_clamped": True})
    assert f"<b>Jig:</b> {NOTE}" in render_report_html(report, tmp_path)
    assert f"  jig: {NOTE}" in format_summary(report).splitlines()


def test_no_jig_no_line(tmp_path: Path) -> None:
    report = _report({})
    assert "Jig:" not in render_report_html(report, tmp_path)
    assert "jig:" not in format_summary(report)
