"""detection_precision's report from made-up trial rows: grid cells, maxima, random-scene statistics, targets."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from asmteach.plugins.detectors.cvfh.precision_report import write_precision_report


def _row(quarter: str, kind: str, x: float, found: bool = True) -> dict[str, Any]:
    """One trial's metrics: rough and corrected errors (mm, deg) and stage times (ms)."""
    row: dict[str, Any] = {
        "kind": kind,
        "detector": "cvfh_icp",
        "part": "peg",
        "placement": 0,
        "cell": "peg#0",
        "quarter": quarter,
        "x_mm": 450.0,
        "y_mm": 0.0,
        "yaw_deg": 10.0,
        "found": found,
        "reason": "" if found else "not found",
        "success": found and abs(x) <= 5.0,
        "t_detect": 100.0,
        "t_correct": 20.0,
        "t_total": 120.0,
    }
    if found:
        for label in ("rough", "corr"):
            row.update({f"{label}_{c}": 0.0 for c in ("y", "z", "roll", "pitch", "yaw")})
            row.update({f"{label}_x": x, f"{label}_pos": abs(x), f"{label}_rot": 0.5})
    return row


def test_report_marks_the_largest_error_and_states_the_targets(tmp_path: Path) -> None:
    metrics = [
        _row("near_left", "cell", 1.0),
        _row("near_right", "cell", -3.0),
        _row("", "random", 0.8),
        _row("", "random", 0.0, found=False),
    ]
    rows = [{"ok": True, "metrics": m} for m in metrics] + [{"ok": False, "error": "boom"}]
    md_path, csv_path = write_precision_report(rows, tmp_path)
    md = md_path.read_text()
    assert "1 trials failed with an error" in md
    assert "## Grid: cvfh_icp" in md and "**-3.0**" in md and "**+1.0**" not in md
    assert "mean abs" in md and "(2.0, 0.0, 0.0)" in md  # mean |x| over the two quarters
    assert "success (<= 5 mm and <= 5 deg) >= 99 %: 50.0 -> NOT met" in md
    assert "median detection time <= 150 ms (wall clock): 100.0 -> met" in md
    assert "## Random scenes that missed" in md
    csv = csv_path.read_text()
    assert "peg#0" in csv and "near_right" in csv
