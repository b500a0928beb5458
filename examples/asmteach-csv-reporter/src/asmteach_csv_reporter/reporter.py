"""A reporter hook: ``run_summary.csv`` with one row per run.

asmteach finds this object through the entry point ``csv_reporter`` in the
group ``asmteach.hooks`` (see this package's ``pyproject.toml``) and
registers its ``@hookimpl`` methods with its pluggy plugin manager. Nothing
in asmteach names this package.

Columns, in order: ``config`` (the config's ``name``), ``seed``,
``success``, ``failed_stage``, ``reason``, then ``stage_<stage>_s`` (wall
seconds of each stage, in run order) and ``metric_<name>`` (each metric of
the report, e.g. achieved errors in mm and deg, in the report's own units).
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

from asmteach.core.hooks import hookimpl
from asmteach.core.io import write_text

__all__ = ["FILENAME", "CsvReporter", "plugin", "summary_row"]

FILENAME = "run_summary.csv"


def summary_row(report: dict[str, Any], observed_seconds: dict[str, float] | None = None) -> dict[str, Any]:
    """The CSV row of a run report (a ``RunReport`` dumped in JSON mode).

    Stage times come from the report's ``stages``; stages the report does
    not list but that were observed finishing (``observed_seconds``, stage
    -> seconds) are added after them.
    """
    row: dict[str, Any] = {
        "config": (report.get("config") or {}).get("name", ""),
        "seed": report.get("seed"),
        "success": bool(report.get("success")),
        "failed_stage": report.get("failed_stage") or "",
        "reason": report.get("reason") or "",
    }
    seconds = {s["stage"]: s.get("seconds") for s in report.get("stages") or []}
    for stage, secs in (observed_seconds or {}).items():
        seconds.setdefault(stage, secs)
    row.update({f"stage_{stage}_s": round(float(secs), 4) for stage, secs in seconds.items() if secs is not None})
    row.update({f"metric_{name}": value for name, value in (report.get("metrics") or {}).items()})
    return row


class CsvReporter:
    """Records stage times as stages finish; writes the CSV when the report is final."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    @hookimpl
    def asmteach_stage_finished(self, stage: str, ok: bool, seconds: float, summary: dict[str, Any]) -> None:
        self.seconds[stage] = float(seconds)

    @hookimpl
    def asmteach_report_ready(self, report: dict[str, Any], out_dir: Path) -> list[Path]:
        row = summary_row(report, self.seconds)
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=list(row))
        writer.writeheader()
        writer.writerow(row)
        # Atomic (temporary file + rename), so an interrupted run never leaves half a CSV.
        path = write_text(Path(out_dir) / FILENAME, buf.getvalue())
        self.seconds = {}  # the next run in this process starts afresh
        return [path]


plugin = CsvReporter()
"""The object the entry point names; pluggy registers its hook implementations."""
