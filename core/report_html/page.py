"""The run report as one self-contained HTML page: inline CSS, every figure embedded as a ``data:`` URI."""

from __future__ import annotations

import base64
import html
from pathlib import Path
from typing import Any

import numpy as np

from asmteach.core.io import write_text
from asmteach.core.models import RunReport
from asmteach.core.report_html.facts import (
    ROBOT_KINDS,
    format_value,
    pose_text,
    recorded_errors,
    robot_clock,
    true_pose,
    vector_text,
)

IMAGE_TYPES: dict[str, str] = {
    ".png": "image/png",
    ".gif": "image/gif",
    ".svg": "image/svg+xml",
    ".jpg": "image/jpeg",
    ".jpeg": "image/jpeg",
}
"""Artefact suffixes embedded as images, with their MIME types."""

_CSS = """
:root { --ok: #1b7f3b; --bad: #b3261e; --muted: #5f6368; --line: #d0d4d9; --head: #f1f3f4; }
* { box-sizing: border-box; }
body { font: 15px/1.45 system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; color: #202124;
       max-width: 1100px; margin: 2em auto; padding: 0 1.2em; }
h1 { font-size: 1.6em; margin: 0 0 .2em; }
h2 { font-size: 1.2em; margin: 1.8em 0 .5em; border-bottom: 2px solid var(--line); padding-bottom: .2em; }
h3 { font-size: 1.02em; margin: 1.1em 0 .4em; }
.meta { color: var(--muted); margin: 0 0 .8em; }
.status { display: inline-block; padding: .35em .8em; border-radius: 4px; font-weight: 600; color: #fff; }
.status.ok { background: var(--ok); } .status.bad { background: var(--bad); }
.reason { margin: .5em 0 0; }
table { border-collapse: collapse; margin: .4em 0 1em; font-size: .93em; }
th, td { border: 1px solid var(--line); padding: .3em .6em; text-align: left; vertical-align: top; }
th { background: var(--head); font-weight: 600; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
td.ok { color: var(--ok); font-weight: 600; } td.bad { color: var(--bad); font-weight: 600; }
td.details { font-family: ui-monospace, Menlo, Consolas, monospace; font-size: .88em; color: #3c4043; }
.none { color: var(--muted); font-style: italic; }
figure { margin: 1em 0 1.6em; }
figure img { max-width: 100%; height: auto; border: 1px solid var(--line); }
figcaption { color: var(--muted); font-size: .9em; margin-top: .3em; }
footer { color: var(--muted); font-size: .85em; margin-top: 3em; }
.clocks { display: flex; flex-wrap: wrap; gap: 2em; align-items: flex-start; }
@media print {
  body { margin: 0; max-width: none; font-size: 11pt; }
  .status { color: #000; border: 2px solid #000; background: none !important; }
  h2 { break-after: avoid; } table, figure { break-inside: avoid; }
}
"""


# ---------------------------------------------------------------- formatting
def _e(value: Any) -> str:
    """HTML-escaped text of any value (quotes too, so it is safe in attributes)."""
    return html.escape(str(value), quote=True)


def _table(head: list[str], rows: list[list[str]]) -> str:
    """An HTML table; ``head`` is plain text, ``rows`` hold ready cell markup (``<td>...</td>``)."""
    if not rows:
        return '<p class="none">none</p>'
    th = "".join(f"<th>{_e(h)}</th>" for h in head)
    body = "".join("<tr>" + "".join(r) + "</tr>" for r in rows)
    return f"<table><thead><tr>{th}</tr></thead><tbody>{body}</tbody></table>"


def _td(value: Any, cls: str = "") -> str:
    klass = f' class="{cls}"' if cls else ""
    return f"<td{klass}>{_e(value)}</td>"


def _num(value: Any) -> str:
    return _td(format_value(value), "num")


def _kv_table(items: dict[str, Any]) -> str:
    return _table(
        ["key", "value"], [[_td(k), _num(v) if _is_number(v) else _td(format_value(v))] for k, v in items.items()]
    )


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _details_text(details: dict[str, Any], limit: int = 6) -> str:
    """The first scalar-ish details as ``key=value``; long values are cut."""
    parts = [f"{k}={format_value(v, 40)}" for k, v in list(details.items())[:limit]]
    if len(details) > limit:
        parts.append(f"(+{len(details) - limit} more)")
    return "; ".join(parts)


# ---------------------------------------------------------------- sections
def _header(report: RunReport) -> str:
    name = report.config.get("name") or "run"
    if report.success:
        status = '<span class="status ok">SUCCESS</span>'
        reason = ""
    else:
        stage = report.failed_stage or "unknown stage"
        status = f'<span class="status bad">FAILED at {_e(stage)}</span>'
        cause = report.failure_cause.value if report.failure_cause is not None else "not recorded"
        reason = (
            f'<p class="reason"><b>Cause:</b> <code>{_e(cause)}</code> · '
            f"<b>Reason:</b> {_e(report.reason or 'not recorded')}</p>"
        )
    # a plan that relies on a jig says so where the user looks first (asmteach.core.arm.fixture)
    reason += "".join(
        f'<p class="reason"><b>Jig:</b> {_e(s.details["jig"])}</p>' for s in report.stages if s.details.get("jig")
    )
    total = sum(s.seconds for s in report.stages)
    meta = f"seed {report.seed} · {len(report.stages)} stages · computer {total:.2f} s"
    robot = robot_clock(report)
    if robot.get("total") is not None:
        meta += f" · robot {robot['total']:.2f} s of motion"
    return f'<header><h1>{_e(name)}</h1><p class="meta">{_e(meta)}</p>{status}{reason}</header>'


def _stages_section(report: RunReport) -> str:
    rows = [
        [
            _td(s.stage),
            _td("ok" if s.ok else "failed", "ok" if s.ok else "bad"),
            _td(f"{s.seconds:.2f}", "num"),
            _td(s.reason or ""),
            _td(_details_text(s.details), "details"),
        ]
        for s in report.stages
    ]
    return "<h2>Stages</h2>" + _table(["stage", "ok", "seconds", "reason", "details"], rows)


def _clocks_section(report: RunReport) -> str:
    """Both clocks side by side: the robot's (simulated motion, by kind) and the computer's (per stage)."""
    executed = report.robot_seconds or {}
    planned = report.plan_stats.get("robot_seconds") or {}
    old = report.plan_stats.get("robot_seconds_trapezoid") or {}
    timing = report.plan_stats.get("timing", "")
    rows = []
    for kind in ("total", *ROBOT_KINDS):
        if not any(kind in d for d in (executed, planned, old)):
            continue
        rows.append([_td(kind)] + [_num(d[kind]) if kind in d else _td("") for d in (executed, planned, old)])
    robot = _table(["motion", "executed s", f"planned s ({timing or 'timing'})", "trapezoid s (same paths)"], rows)
    clock = report.computer_seconds or {s.stage: s.seconds for s in report.stages}
    computer = _table(["stage", "seconds"], [[_td(k), _num(v)] for k, v in clock.items()])
    return (
        '<h2>Clocks</h2><div class="clocks"><div><h3>Robot (simulated motion)</h3>'
        + robot
        + "</div><div><h3>Computer (wall time)</h3>"
        + computer
        + "</div></div>"
    )


def _task_section(report: RunReport) -> str:
    task = report.task
    if task is None:
        return '<h2>Taught task</h2><p class="none">no task was taught</p>'
    xyz, rpy = pose_text(task.T_A_B)
    rows = [
        [_td("structure"), _td(task.name)],
        [_td("parts"), _td(f"A = {task.part_a.name}, B = {task.part_b.name}")],
        [_td("T_A_B position (mm)"), _td(xyz, "num")],
        [_td("T_A_B roll, pitch, yaw (deg)"), _td(rpy, "num")],
        [_td("insertion direction v_a (A frame)"), _td(vector_text(task.v_a, 4), "num")],
    ]
    out = "<h2>Taught task</h2>" + _table(["quantity", "value"], rows)
    ev = task.evidence
    if ev is not None:
        res = np.asarray(ev.residuals_px, dtype=float)
        evidence = {
            "frames used": f"{len(ev.frames_used)} of {ev.frames_total}",
            "reprojection RMS (px), median / max": (f"{np.median(res):.3f} / {np.max(res):.3f}" if res.size else None),
            "spread (mm)": ev.spread_mm,
            "spread (deg)": ev.spread_deg,
            "insertion direction from": ev.insertion_source,
        }
        out += "<h3>Teaching evidence</h3>" + _kv_table(evidence)
        if ev.notes:
            out += "<ul>" + "".join(f"<li>{_e(n)}</li>" for n in ev.notes) + "</ul>"
    return out


def _detections_section(report: RunReport) -> str:
    rows = []
    for det in report.detections:
        T_true = true_pose(det)
        poses = [("rough", det.rough), ("corrected", det.corrected)]
        if not det.found or all(T is None for _, T in poses):
            rows.append(
                [
                    _td(det.part),
                    _td("not found", "bad"),
                    _td("", "num"),
                    _td("", "num"),
                    _td("", "num"),
                    _td("", "num"),
                    _td(det.reason or ""),
                ]
            )
            continue
        for label, T in poses:
            if T is None:
                continue
            xyz, rpy = pose_text(T)
            err_pos = err_rot = ""
            if T_true is not None:
                err = recorded_errors(det, label, T, T_true)
                err_pos = f"{err['position_mm']:.2f} ({vector_text(err['dxyz_mm'])})"
                err_rot = f"{err['angle_deg']:.2f}"
            note = []
            if label == "rough" and det.fitness is not None:
                note.append(f"fitness {det.fitness:.3f}")
            if label == "rough" and det.inlier_rmse is not None:
                note.append(f"inlier RMSE {det.inlier_rmse * 1000:.2f} mm")
            if label == "rough" and det.timing_ms:
                note.append(f"{sum(det.timing_ms.values()):.0f} ms")
            rows.append(
                [
                    _td(det.part),
                    _td(label),
                    _td(xyz, "num"),
                    _td(rpy, "num"),
                    _td(err_pos, "num"),
                    _td(err_rot, "num"),
                    _td(", ".join(note)),
                ]
            )
    head = ["part", "pose", "x, y, z (mm)", "roll, pitch, yaw (deg)", "error (mm) (dx, dy, dz)", "error (deg)", "notes"]
    known = any(true_pose(d) is not None for d in report.detections)
    note = "" if known or not report.detections else '<p class="none">true poses not recorded; no errors shown</p>'
    return "<h2>Detections</h2>" + _table(head, rows) + note


def _artefacts_section(report: RunReport, out_dir: Path) -> str:
    figures, files = [], []
    root = out_dir.resolve()
    for name, rel in report.artefacts.items():
        path = (out_dir / rel).resolve()
        if not path.is_relative_to(root):
            files.append([_td(name), _td(rel), _td("outside the output folder; not embedded", "bad")])
            continue
        mime = IMAGE_TYPES.get(path.suffix.lower())
        if mime is None:
            link = f'<td><a href="{_e(Path(rel).as_posix())}">{_e(rel)}</a></td>'
            files.append([_td(name), link, _td("" if path.is_file() else "missing", "" if path.is_file() else "bad")])
            continue
        if not path.is_file():
            files.append([_td(name), _td(rel), _td("missing", "bad")])
            continue
        data = base64.b64encode(path.read_bytes()).decode("ascii")
        figures.append(
            f'<figure><img src="data:{mime};base64,{data}" alt="{_e(name)}">'
            f"<figcaption>{_e(name)} <span>({_e(rel)})</span></figcaption></figure>"
        )
    out = "<h2>Figures</h2>" + ("".join(figures) if figures else '<p class="none">no figures</p>')
    if files:
        out += "<h2>Other files</h2>" + _table(["artefact", "file", "status"], files)
    return out


def render_report_html(report: RunReport, out_dir: Path) -> str:
    """The HTML text of the report; artefact paths are read relative to ``out_dir``."""
    name = report.config.get("name") or "run"
    outcome = "success" if report.success else f"failed at {report.failed_stage or '?'}"
    sections = [
        _header(report),
        _stages_section(report),
        _clocks_section(report),
        _task_section(report),
        _detections_section(report),
        "<h2>Plan</h2>" + _kv_table(report.plan_stats),
        "<h2>Achieved errors and metrics</h2>" + _kv_table(report.metrics),
        _artefacts_section(report, Path(out_dir)),
        "<footer>Written by asmteach. Positions in mm, angles in degrees; report.json holds metres and "
        "radians.</footer>",
    ]
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{_e(name)} (seed {report.seed}): {_e(outcome)}</title><style>{_CSS}</style></head>"
        "<body>" + "\n".join(sections) + "</body></html>\n"
    )


def write_report_html(report: RunReport, out_dir: Path) -> Path:
    """Write ``out_dir/report.html`` atomically; returns its path.

    Every image artefact (``report.artefacts``: name -> path relative to
    ``out_dir``) is embedded, so the file stands alone.
    """
    out = Path(out_dir)
    return write_text(out / "report.html", render_report_html(report, out))
