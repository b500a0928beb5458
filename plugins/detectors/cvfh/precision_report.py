"""The ``detection_precision`` experiment's report: grid tables, random-scene statistics, stage times, targets.

Reads the rows :class:`~asmteach.plugins.detectors.cvfh.experiment.DetectionPrecision` trials return
(errors in mm, world axes, and deg; times in ms) and writes ``detection_precision.md`` (cell tables with
maxima marked and a mean-absolute row, the random-scene distributions, per-stage times and the targets)
and ``detection_precision_cells.csv``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from asmteach.core.io import write_text
from asmteach.core.sweep import to_csv, to_markdown
from asmteach.plugins.detectors.cvfh.scenes import QUARTERS

__all__ = ["write_precision_report"]

COMPONENTS = ("x", "y", "z", "roll", "pitch", "yaw")


def write_precision_report(rows: list[dict[str, Any]], out_dir: Path) -> list[Path]:
    """Write ``detection_precision.md`` and ``detection_precision_cells.csv`` into ``out_dir`` from the sweep's rows.

    ``rows`` are the sweep's trial records (``ok`` and the trial's ``metrics``, see
    :meth:`DetectionPrecision.run_trial`); returns the paths written.
    """
    metrics = [r["metrics"] for r in rows if r.get("ok")]
    failed = [r for r in rows if not r.get("ok")]
    detectors = sorted({m["detector"] for m in metrics})
    md = ["# Detection precision (execution phase)\n"]
    md.append(
        "Errors: estimate minus ground truth (symmetry-aware). Position: part origin, mm, world axes. "
        "Rotation: roll, pitch, yaw of R_est R_true^T, deg. **Bold** = largest |value| of that component "
        "over the grid (per detector, rough and corrected separately).\n"
    )
    if failed:
        md.append(f"{len(failed)} trials failed with an error (see summary.md).\n")
    cell_rows: list[dict[str, Any]] = []
    for name in detectors:
        cells = [m for m in metrics if m["detector"] == name and m["kind"] == "cell"]
        if cells:
            table, flat = _cell_table(cells)
            md.append(f"\n## Grid: {name} (placements x table quarters)\n\n{table}")
            cell_rows += flat
    md.append("\n## Random scenes\n\n")
    stats = [
        _random_stats(name, [m for m in metrics if m["detector"] == name and m["kind"] == "random"])
        for name in detectors
    ]
    stats = [s for s in stats if s]
    md.append(to_markdown(stats) if stats else "_no random scenes_\n")
    md.append("\n## Time per stage (random scenes, median ms)\n\n")
    md.append(to_markdown([_stage_times(name, metrics) for name in detectors]))
    md.append("\n## Targets (cvfh_icp, random scenes)\n\n" + _targets(stats))
    misses = [m for m in metrics if m["kind"] == "random" and not m["success"]]
    if misses:
        md.append("\n## Random scenes that missed (first 30)\n\n")
        md.append(
            to_markdown(
                [
                    {
                        k: m.get(k)
                        for k in (
                            "detector",
                            "cell",
                            "x_mm",
                            "y_mm",
                            "yaw_deg",
                            "found",
                            "reason",
                            "corr_pos",
                            "corr_rot",
                            "rough_pos",
                            "rough_rot",
                        )
                    }
                    for m in misses[:30]
                ]
            )
        )
    paths = [
        write_text(out_dir / "detection_precision.md", "".join(md)),
        write_text(out_dir / "detection_precision_cells.csv", to_csv(cell_rows) if cell_rows else ""),
    ]
    return paths


def _fmt(v: float | None, bold: bool) -> str:
    if v is None:
        return "-"
    s = f"{v:+.1f}"
    return f"**{s}**" if bold and abs(v) >= 0.05 else s


def _cell_table(cells: list[dict[str, Any]]) -> tuple[str, list[dict[str, Any]]]:
    """Markdown grid (quarters x placements, then the mean-absolute row) and its flat rows."""
    names = list(dict.fromkeys(m["cell"] for m in sorted(cells, key=lambda m: (m["part"], m["placement"]))))
    quarters = list(QUARTERS)
    by = {(m["cell"], m["quarter"]): m for m in cells}
    argmax: dict[str, tuple[str, str]] = {}
    for label in ("rough", "corr"):
        for c in COMPONENTS:
            key = f"{label}_{c}"
            vals = [(abs(m[key]), (m["cell"], m["quarter"])) for m in cells if m.get(key) is not None]
            if vals:
                argmax[key] = max(vals)[1]

    def cell_text(m: dict[str, Any] | None) -> str:
        if m is None:
            return "-"
        if not m.get("found"):
            return f"not found: {m.get('reason', '')[:60]}"
        parts = []
        for label, tag in (("rough", "R"), ("corr", "C")):
            vals = [
                _fmt(m.get(f"{label}_{c}"), argmax.get(f"{label}_{c}") == (m["cell"], m["quarter"])) for c in COMPONENTS
            ]
            parts.append(f"{tag} ({', '.join(vals[:3])}) ({', '.join(vals[3:])})")
        return "<br>".join(parts)

    records = []
    flat = []
    for q in quarters:
        rec = {"quarter": q}
        for n in names:
            m = by.get((n, q))
            rec[n] = cell_text(m)
            if m is not None:
                flat.append({"cell": n, "quarter": q, **{k: m.get(k) for k in m if k.startswith(("rough_", "corr_"))}})
        records.append(rec)
    mean = {"quarter": "mean abs"}
    for n in names:
        ms = [by[(n, q)] for q in quarters if (n, q) in by and by[(n, q)].get("found")]
        if not ms:
            mean[n] = "-"
            continue
        parts = []
        for label, tag in (("rough", "R"), ("corr", "C")):
            vals = [
                float(np.mean([abs(m[f"{label}_{c}"]) for m in ms if f"{label}_{c}" in m] or [np.nan]))
                for c in COMPONENTS
            ]
            xyz, rpy = ", ".join(f"{v:.1f}" for v in vals[:3]), ", ".join(f"{v:.1f}" for v in vals[3:])
            parts.append(f"{tag} ({xyz}) ({rpy})")
        mean[n] = "<br>".join(parts)
    records.append(mean)
    legend = "R = rough, C = corrected; (x, y, z) mm (roll, pitch, yaw) deg.\n\n"
    return legend + to_markdown(records), flat


def _pct(vals: list[float], q: float) -> float | None:
    return round(float(np.percentile(vals, q)), 3) if vals else None


def _random_stats(name: str, ms: list[dict[str, Any]]) -> dict[str, Any] | None:
    if not ms:
        return None
    rec: dict[str, Any] = {"detector": name, "scenes": len(ms)}
    rec["found_%"] = round(100.0 * np.mean([bool(m["found"]) for m in ms]), 1)
    rec["success_%"] = round(100.0 * np.mean([bool(m["success"]) for m in ms]), 1)
    for label in ("rough", "corr"):
        for what, unit in (("pos", "mm"), ("rot", "deg")):
            vals = [m[f"{label}_{what}"] for m in ms if f"{label}_{what}" in m]
            rec[f"{label}_{what}_{unit}_median"] = _pct(vals, 50)
            rec[f"{label}_{what}_{unit}_p95"] = _pct(vals, 95)
            rec[f"{label}_{what}_{unit}_max"] = round(max(vals), 3) if vals else None
    # Detector alone (the correction is the same for every detector and reported on its own).
    detect = [m.get("t_detect", m.get("t_total")) for m in ms if "t_total" in m]
    cpu = [m["t_cpu"] for m in ms if "t_cpu" in m]
    rec["detect_ms_median"] = _pct(detect, 50)
    rec["detect_ms_p95"] = _pct(detect, 95)
    rec["detect_cpu_ms_median"] = _pct(cpu, 50)
    rec["correct_ms_median"] = _pct([m["t_correct"] for m in ms if "t_correct" in m], 50)
    return rec


def _stage_times(name: str, metrics: list[dict[str, Any]]) -> dict[str, Any]:
    ms = [m for m in metrics if m["detector"] == name and m["kind"] == "random"]
    stages = list(dict.fromkeys(k for m in ms for k in m if k.startswith("t_")))
    rec: dict[str, Any] = {"detector": name}
    for st in stages:
        vals = [m[st] for m in ms if st in m]
        rec[st[2:]] = _pct(vals, 50)
    return rec


def _targets(stats: list[dict[str, Any]]) -> str:
    by = {s["detector"]: s for s in stats}
    cv, fp = by.get("cvfh_icp"), by.get("fpfh_ransac")
    if cv is None:
        return "_cvfh_icp has no random scenes_\n"

    def line(label: str, value: Any, ok: bool) -> str:
        return f"- {label}: {value} -> {'met' if ok else 'NOT met'}\n"

    out = ""
    out += line("corrected max position error <= 1.5 mm", cv["corr_pos_mm_max"], (cv["corr_pos_mm_max"] or 1e9) <= 1.5)
    out += line("corrected max rotation error <= 2 deg", cv["corr_rot_deg_max"], (cv["corr_rot_deg_max"] or 1e9) <= 2)
    out += line("success (<= 5 mm and <= 5 deg) >= 99 %", cv["success_%"], cv["success_%"] >= 99.0)
    for key, what in (("detect_ms_median", "wall clock"), ("detect_cpu_ms_median", "CPU time")):
        value = cv.get(key)
        out += line(f"median detection time <= 150 ms ({what})", value, (value or 1e9) <= 150)
        if fp is not None and fp.get(key) is not None:
            out += line(f"no slower than fpfh_ransac ({what}: {fp[key]} ms)", value, (value or 1e9) <= fp[key])
    return out + "\nAll scenes are synthetic (the virtual Kinect v1 of asmteach.core.perception.depth_camera).\n"
