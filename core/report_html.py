"""A run report a person wants to look at: one self-contained ``report.html`` and a console summary.

:func:`write_report_html` turns a :class:`~asmteach.core.models.RunReport`
into a single HTML file with inline CSS and every figure the run wrote (the
PNG/GIF/SVG/JPEG files named in ``report.artefacts``) embedded as base64
``data:`` URIs, so it can be mailed, archived or printed on its own: it
names no external URL. :func:`format_summary` gives the same facts in at
most 25 plain-text lines for the console.

Units on the page: positions in millimetres, angles in degrees (poses as
``x, y, z`` mm and fixed-axis ``roll, pitch, yaw`` deg); everything in the
report itself is metres and radians.

Detection errors are computed when a detection's ``details`` holds the
simulator's true pose under one of :data:`TRUE_POSE_KEYS` (a 4x4
``T_world_part``). They are plain errors of the estimate against that pose,
not reduced over the part's symmetries.
"""

from __future__ import annotations

import base64
import html
import json
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from asmteach.core import geometry
from asmteach.core.io import write_text
from asmteach.core.models import Detection, RunReport

__all__ = ["IMAGE_TYPES", "TRUE_POSE_KEYS", "format_summary", "pose_errors", "render_report_html", "write_report_html"]

TRUE_POSE_KEYS: tuple[str, ...] = ("T_world_part_true", "T_world_true", "T_true")
"""Keys of ``Detection.details`` read as the true ``T_world_part`` (4x4, metres), first found wins."""

IMAGE_TYPES: dict[str, str] = {
    ".png": "image/png",
    ".gif": "image/gif",
    ".svg": "image/svg+xml",
    ".jpg": "image/jpeg",
    ".jpeg": "image/jpeg",
}
"""Artefact suffixes embedded as images, with their MIME types."""

SUMMARY_MAX_LINES = 25
_WIDTH = 100  # console summary line width

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


def _fmt(value: Any, width: int = 160) -> str:
    """Compact text of a report value (floats to 4 significant digits)."""
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.4g}" if math.isfinite(value) else str(value)
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, list | tuple | dict):
        text = json.dumps(value, default=str, separators=(", ", ": "))
        if isinstance(value, list | tuple) and all(isinstance(v, int | float) for v in value):
            text = "[" + ", ".join(_fmt(v) for v in value) + "]"
    else:
        text = str(value)
    return text if len(text) <= width else text[: width - 1] + "…"


def _vec(values: Iterable[float], digits: int = 2) -> str:
    return ", ".join(f"{v:+.{digits}f}" for v in values)


def _pose_text(T: np.ndarray) -> tuple[str, str]:
    """``("x, y, z" in mm, "roll, pitch, yaw" in deg)`` of a 4x4 transform."""
    p = geometry.to_xyz_mm_rpy_deg(T)
    return _vec(p["xyz_mm"]), _vec(p["rpy_deg"])


def _true_pose(det: Detection) -> np.ndarray | None:
    """The true ``T_world_part`` stored in ``det.details``, or None (also when malformed)."""
    for key in TRUE_POSE_KEYS:
        if key in det.details:
            try:
                T = np.asarray(det.details[key], dtype=float).reshape(4, 4)
            except (TypeError, ValueError):
                return None
            return T if np.all(np.isfinite(T)) else None
    return None


def _recorded_errors(det: Any, label: str, T: np.ndarray, T_true: np.ndarray) -> dict[str, Any]:
    """:func:`pose_errors`, with distance and angle as the run recorded them (modulo the part's symmetries)."""
    err = pose_errors(T, T_true)
    rec = det.details.get(f"{label}_error") or {}
    err["pos_mm"] = rec.get("position_mm", err["pos_mm"])
    err["rot_deg"] = rec.get("angle_deg", err["rot_deg"])
    return err


def pose_errors(T_est: np.ndarray, T_true: np.ndarray) -> dict[str, Any]:
    """Errors of an estimated pose against the true one (both ``T_world_part``, metres).

    Returns ``pos_mm`` (distance of the origins), ``dxyz_mm`` (estimate minus
    truth, world axes, ``(3,)``) and ``rot_deg`` (geodesic angle of
    ``R_est^T R_true``).
    """
    d = (np.asarray(T_est, float)[:3, 3] - np.asarray(T_true, float)[:3, 3]) * 1000.0
    return {
        "pos_mm": float(np.linalg.norm(d)),
        "dxyz_mm": d.tolist(),
        "rot_deg": math.degrees(geometry.rotation_distance(T_est, T_true)),
    }


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
    return _td(_fmt(value), "num")


def _kv_table(items: dict[str, Any]) -> str:
    return _table(["key", "value"], [[_td(k), _num(v) if _is_number(v) else _td(_fmt(v))] for k, v in items.items()])


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _details_text(details: dict[str, Any], limit: int = 6) -> str:
    """The first scalar-ish details as ``key=value``; long values are cut."""
    parts = [f"{k}={_fmt(v, 40)}" for k, v in list(details.items())[:limit]]
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
        reason = f'<p class="reason"><b>Reason:</b> {_e(report.reason or "not recorded")}</p>'
    total = sum(s.seconds for s in report.stages)
    meta = f"seed {report.seed} · {len(report.stages)} stages · computer {total:.2f} s"
    robot = _robot_clock(report)
    if robot.get("total") is not None:
        meta += f" · robot {robot['total']:.2f} s of motion"
    return f"<header><h1>{_e(name)}</h1><p class=\"meta\">{_e(meta)}</p>{status}{reason}</header>"


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


_ROBOT_KINDS = ("transit", "approach", "insertion", "regrasp")


def _robot_clock(report: RunReport) -> dict[str, float]:
    """The robot seconds to show: those executed, else the plan's (seconds of simulated motion)."""
    if report.robot_seconds:
        return dict(report.robot_seconds)
    planned = report.plan_stats.get("robot_seconds")
    return dict(planned) if isinstance(planned, dict) else {}


def _clocks_section(report: RunReport) -> str:
    """Both clocks side by side: the robot's (simulated motion, by kind) and the computer's (per stage)."""
    executed = report.robot_seconds or {}
    planned = report.plan_stats.get("robot_seconds") or {}
    old = report.plan_stats.get("robot_seconds_trapezoid") or {}
    timing = report.plan_stats.get("timing", "")
    rows = []
    for kind in ("total", *_ROBOT_KINDS):
        if not any(kind in d for d in (executed, planned, old)):
            continue
        rows.append([_td(kind)] + [_num(d[kind]) if kind in d else _td("") for d in (executed, planned, old)])
    robot = _table(["motion", "executed s", f"planned s ({timing or 'timing'})", "trapezoid s (same paths)"], rows)
    clock = report.computer_seconds or {s.stage: s.seconds for s in report.stages}
    computer = _table(["stage", "seconds"], [[_td(k), _num(v)] for k, v in clock.items()])
    return ('<h2>Clocks</h2><div class="clocks"><div><h3>Robot (simulated motion)</h3>' + robot
            + "</div><div><h3>Computer (wall time)</h3>" + computer + "</div></div>")


def _task_section(report: RunReport) -> str:
    task = report.task
    if task is None:
        return '<h2>Taught task</h2><p class="none">no task was taught</p>'
    xyz, rpy = _pose_text(task.T_A_B)
    rows = [
        [_td("structure"), _td(task.name)],
        [_td("parts"), _td(f"A = {task.part_a.name}, B = {task.part_b.name}")],
        [_td("T_A_B position (mm)"), _td(xyz, "num")],
        [_td("T_A_B roll, pitch, yaw (deg)"), _td(rpy, "num")],
        [_td("insertion direction v_a (A frame)"), _td(_vec(task.v_a, 4), "num")],
    ]
    out = "<h2>Taught task</h2>" + _table(["quantity", "value"], rows)
    ev = task.evidence
    if ev is not None:
        res = np.asarray(ev.residuals_px, dtype=float)
        evidence = {
            "frames used": f"{len(ev.frames_used)} of {ev.frames_total}",
            "reprojection RMS (px), median / max": (
                f"{np.median(res):.3f} / {np.max(res):.3f}" if res.size else None
            ),
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
        T_true = _true_pose(det)
        poses = [("rough", det.rough), ("corrected", det.corrected)]
        if not det.found or all(T is None for _, T in poses):
            rows.append([_td(det.part), _td("not found", "bad"), _td("", "num"), _td("", "num"),
                         _td("", "num"), _td("", "num"), _td(det.reason or "")])
            continue
        for label, T in poses:
            if T is None:
                continue
            xyz, rpy = _pose_text(T)
            err_pos = err_rot = ""
            if T_true is not None:
                err = _recorded_errors(det, label, T, T_true)
                err_pos = f"{err['pos_mm']:.2f} ({_vec(err['dxyz_mm'])})"
                err_rot = f"{err['rot_deg']:.2f}"
            note = []
            if label == "rough" and det.fitness is not None:
                note.append(f"fitness {det.fitness:.3f}")
            if label == "rough" and det.inlier_rmse is not None:
                note.append(f"inlier RMSE {det.inlier_rmse * 1000:.2f} mm")
            if label == "rough" and det.timing_ms:
                note.append(f"{sum(det.timing_ms.values()):.0f} ms")
            rows.append([_td(det.part), _td(label), _td(xyz, "num"), _td(rpy, "num"),
                         _td(err_pos, "num"), _td(err_rot, "num"), _td(", ".join(note))])
    head = ["part", "pose", "x, y, z (mm)", "roll, pitch, yaw (deg)", "error (mm) (dx, dy, dz)", "error (deg)", "notes"]
    known = any(_true_pose(d) is not None for d in report.detections)
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
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
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


# ---------------------------------------------------------------- console
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
        lines.append(f"  reason: {report.reason or 'not recorded'}")
    if report.stages:
        lines.append("stages:")
        stages = report.stages[:8]
        for s in stages:
            status = "ok" if s.ok else "FAILED"
            tail = f"  {s.reason}" if s.reason else ""
            lines.append(f"  {s.stage:<14} {status:<6} {s.seconds:8.2f} s{tail}")
        if len(report.stages) > len(stages):
            lines.append(f"  ... {len(report.stages) - len(stages)} more stages")
    robot = _robot_clock(report)
    if robot.get("total") is not None:
        split = ", ".join(f"{k} {robot[k]:.1f}" for k in _ROBOT_KINDS if robot.get(k))
        lines.append(f"clocks: robot {robot['total']:.1f} s of motion, computer "
                     f"{sum(s.seconds for s in report.stages):.1f} s (robot: {split})")
    if report.task is not None:
        xyz, rpy = _pose_text(report.task.T_A_B)
        lines.append(f"task {report.task.name}: T_A_B [{xyz}] mm  [{rpy}] deg")
    if report.detections:
        lines.append("detections:")
        for det in report.detections[:4]:
            T = det.best
            if not det.found or T is None:
                lines.append(f"  {det.part}: not found ({det.reason or 'no reason recorded'})")
                continue
            xyz, _ = _pose_text(T)
            T_true = _true_pose(det)
            err = ""
            if T_true is not None:
                e = _recorded_errors(det, "corrected" if det.corrected is not None else "rough", T, T_true)
                err = f"  error {e['pos_mm']:.2f} mm / {e['rot_deg']:.2f} deg"
            lines.append(f"  {det.part}: [{xyz}] mm{err}")
    if report.metrics:
        lines.append("metrics:")
        items = [f"{k} = {_fmt(v)}" for k, v in report.metrics.items()]
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
