"""Teaching precision experiments (``asmteach sweep``): the paper's 2 sets x 5 structures x 5 orientations
table, and a one-factor-at-a-time sweep showing where precision breaks down.

Each trial renders a demonstration in memory (:mod:`.scene`), teaches with
the ``aruco`` teacher and compares with the structure's ground truth:
``dd`` is the error of ``|p_A - p_B|`` in mm (as in the paper); ``dr, dp, dy``
are the roll, pitch, yaw (degrees) of the relative-rotation error
``R_true^T R_taught``; ``v_a_err_deg`` the angle between learned and true ``v_a``.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from pydantic import Field, ValidationError

from asmteach.core import geometry
from asmteach.core.config import format_validation_error
from asmteach.core.errors import UserError
from asmteach.core.io import atomic_path, write_text
from asmteach.core.models import StrictModel
from asmteach.core.parts import build_part, load_structure
from asmteach.core.structure_corpus import STRUCTURE_FAMILIES
from asmteach.core.sweep import Experiment, flatten, to_csv
from asmteach.plugins.detectors.aruco.camera import c615_like, load_camera
from asmteach.plugins.detectors.aruco.marker_count import (
    generated_task,
    keep_markers,
    precision_bound,
    write_marker_count_report,
)
from asmteach.plugins.detectors.aruco.scene import DemoSettings, render_demo_frames
from asmteach.plugins.detectors.aruco.teacher import ArucoTeacher

__all__ = ["TeachingBreakdown", "TeachingPrecision", "run_teaching_trial"]


class TeachingParams(StrictModel):
    """One teaching trial."""

    structure: str | None = Field(None, description="structure YAML, relative to the experiment file")
    generated: str | None = Field(None, description="instead: 'family:index' of the generated corpus (seed 0)")
    markers_per_part: int | None = Field(None, ge=1, le=4, description="keep at most this many markers per part")
    camera: str | None = Field(None, description="camera YAML; default: C615-like")
    demo: dict[str, Any] = Field(default_factory=dict, description="DemoSettings overrides (orientation, ...)")
    teacher: dict[str, Any] = Field(default_factory=dict, description="aruco teacher settings")
    marker_scale: float = Field(1.0, gt=0.1, le=2.0, description="scale of every marker's side length")
    vary: str = Field("baseline", description="breakdown: 'name=value' with name a demo key or marker_scale")


def run_teaching_trial(exp_dir: Path, params: TeachingParams, seed: int, workdir: Path | None) -> dict[str, Any]:
    """Render, teach, compare; return the metrics of one trial."""
    with tempfile.TemporaryDirectory() as tmp:
        return _trial(exp_dir, params, seed, workdir, Path(tmp))


def _trial(exp_dir: Path, params: TeachingParams, seed: int, workdir: Path | None, tmp: Path) -> dict[str, Any]:
    from asmteach.core.models import resolve_relative

    if (params.structure is None) == (params.generated is None):
        raise UserError("params: give either structure or generated")
    if params.generated is not None:
        task = generated_task(params.generated, tmp)
    else:
        assert params.structure is not None
        task = load_structure(resolve_relative(params.structure, exp_dir))
    if params.markers_per_part is not None:
        task = keep_markers(task, params.markers_per_part)
    demo = dict(params.demo)
    scale = params.marker_scale
    if params.vary != "baseline":
        name, _, value = params.vary.partition("=")
        if name == "marker_scale":
            scale = float(value)
        else:
            demo[name] = float(value) if "." in value else int(value)
    if scale != 1.0:
        for part in (task.part_a, task.part_b):
            for m in part.markers:
                m.size *= scale
    settings = DemoSettings.model_validate(demo)
    camera = load_camera(resolve_relative(params.camera, exp_dir)) if params.camera else c615_like()
    a, b = build_part(task.part_a), build_part(task.part_b)
    frames, truth = [], []
    for fr, img, _ in render_demo_frames(a, b, task, camera, settings, seed=seed):
        frames.append(img)
        truth.append(fr)
        if workdir is not None and fr.phase == "assembled" and len(frames) == settings.approach_frames + 1:
            with atomic_path(workdir / "first_assembled.jpg") as tmp:
                cv2.imwrite(str(tmp), img)
    t0 = time.perf_counter()
    teacher = ArucoTeacher(params.teacher, seed=seed)
    observed = teacher.observe(frames, camera, task)
    learned = teacher.teach_observed(observed, camera, task)
    seconds = time.perf_counter() - t0
    T_true, T_est = task.T_A_B, learned.T_A_B
    dd = (np.linalg.norm(T_est[:3, 3]) - np.linalg.norm(T_true[:3, 3])) * 1000.0
    drpy = np.degrees(geometry.rpy(T_true[:3, :3].T @ T_est[:3, :3]))
    ev = learned.evidence
    assert ev is not None
    return {
        "structure": task.name,
        "orientation": settings.orientation,
        "dd_mm": float(dd),
        "dr_deg": float(drpy[0]),
        "dp_deg": float(drpy[1]),
        "dy_deg": float(drpy[2]),
        "dt_mm": float(geometry.translation_distance(T_true, T_est) * 1000.0),
        "drot_deg": float(np.degrees(geometry.rotation_distance(T_true, T_est))),
        "v_a_err_deg": float(np.degrees(np.arccos(np.clip(np.dot(learned.v_a, task.v_a), -1.0, 1.0)))),
        "v_a_source": ev.insertion_source,
        "frames_used": len(ev.frames_used),
        "frames_total": ev.frames_total,
        "spread_mm": ev.spread_mm,
        "teach_seconds": seconds,
        "markers_a": len(task.part_a.markers),
        "markers_b": len(task.part_b.markers),
        "markers_per_part": params.markers_per_part,
        **precision_bound(observed, truth, ev.frames_used, T_true, camera),
    }


class TeachingPrecision(Experiment):
    """Paper figure: one cell per (structure, orientation)."""

    Params = TeachingParams

    def check(self, params: TeachingParams) -> None:
        """``demo`` and ``teacher`` by their models before any trial (they stay dicts: the trial ids hash them);
        one of ``structure`` and ``generated``."""
        if (params.structure is None) == (params.generated is None):
            raise UserError("params: give either structure or generated ('family:index')")
        if params.generated is not None:
            family, _, index = params.generated.partition(":")
            if family not in STRUCTURE_FAMILIES or not index.isdigit():
                raise UserError(
                    f"params.generated: {params.generated!r} must be 'family:index' with a family of "
                    f"{', '.join(STRUCTURE_FAMILIES)}"
                )
        for key, model in (("demo", DemoSettings), ("teacher", ArucoTeacher.Settings)):
            try:
                model.model_validate(getattr(params, key))
            except ValidationError as exc:
                raise UserError(format_validation_error(exc, f"params.{key}")) from None

    def run_trial(self, params: TeachingParams, seed: int, workdir: Path) -> dict[str, Any]:
        return run_teaching_trial(self.base_dir, params, seed, workdir)

    def summarize(self, rows: list[dict[str, Any]], out_dir: Path) -> list[Path]:
        """``teaching_table.{csv,md,png}``: cells ``dd (dr, dp, dy)`` and the mean-absolute row."""
        ok = [r["metrics"] for r in rows if r.get("ok")]
        if not ok:
            return []
        if any(m.get("markers_per_part") is not None for m in ok):
            # One structure appears with several marker counts: the per-count report replaces the cell table.
            return write_marker_count_report(rows, out_dir)
        structures = list(dict.fromkeys(m["structure"] for m in ok))
        orients = sorted({m["orientation"] for m in ok})
        cell = {(m["structure"], m["orientation"]): m for m in ok}

        def fmt(m: dict[str, Any] | None) -> str:
            if m is None:
                return "failed"
            return f"{m['dd_mm']:+.2f} ({m['dr_deg']:+.2f}, {m['dp_deg']:+.2f}, {m['dy_deg']:+.2f})"

        means = {}
        for s in structures:
            ms = [cell[(s, o)] for o in orients if (s, o) in cell]
            means[s] = {k: float(np.mean([abs(m[k]) for m in ms])) for k in ("dd_mm", "dr_deg", "dp_deg", "dy_deg")}
        lines = ["| orientation | " + " | ".join(structures) + " |", "|---|" + "---|" * len(structures)]
        for o in orients:
            lines.append(f"| {o} | " + " | ".join(fmt(cell.get((s, o))) for s in structures) + " |")
        lines.append(
            "| mean abs | "
            + " | ".join(
                f"{means[s]['dd_mm']:.2f} ({means[s]['dr_deg']:.2f}, {means[s]['dp_deg']:.2f}, "
                f"{means[s]['dy_deg']:.2f})"
                for s in structures
            )
            + " |"
        )
        allm = {k: float(np.mean([abs(m[k]) for m in ok])) for k in ("dd_mm", "dr_deg", "dp_deg", "dy_deg")}
        worst_d = max(abs(m["dd_mm"]) for m in ok)
        worst_a = max(max(abs(m["dr_deg"]), abs(m["dp_deg"]), abs(m["dy_deg"])) for m in ok)
        va = [m["v_a_err_deg"] for m in ok if m["v_a_source"] == "demonstration"]
        failed = sum(not r.get("ok") for r in rows)
        summary = (
            f"\n{len(ok)} cells ({failed} failed). Mean |dd| {allm['dd_mm']:.3f} mm; mean |dr| {allm['dr_deg']:.3f}, "
            f"|dp| {allm['dp_deg']:.3f}, |dy| {allm['dy_deg']:.3f} deg. Worst cell |dd| {worst_d:.3f} mm, "
            f"worst angle {worst_a:.3f} deg.\n"
            f"v_a from the demonstration in {len(va)}/{len(ok)} cells; error mean {np.mean(va) if va else np.nan:.2f}"
            f" deg, max {max(va) if va else np.nan:.2f} deg. Teaching time median "
            f"{np.median([m['teach_seconds'] for m in ok]):.2f} s for {ok[0]['frames_total']} frames.\n"
        )
        md = "# Teaching precision: dd mm (dr, dp, dy deg)\n\n" + "\n".join(lines) + "\n" + summary
        paths = [write_text(out_dir / "teaching_table.md", md)]
        paths.append(write_text(out_dir / "teaching_table.csv", to_csv([flatten(r) for r in rows])))
        paths.append(self._png(out_dir / "teaching_table.png", structures, orients, cell, means))
        return paths

    @staticmethod
    def _png(path: Path, structures: list[str], orients: list[int], cell: dict, means: dict) -> Path:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        text = [
            [
                (
                    f"{cell[(s, o)]['dd_mm']:+.2f}\n({cell[(s, o)]['dr_deg']:+.2f},{cell[(s, o)]['dp_deg']:+.2f},"
                    f"{cell[(s, o)]['dy_deg']:+.2f})"
                )
                if (s, o) in cell
                else "failed"
                for s in structures
            ]
            for o in orients
        ]
        text.append(
            [
                f"{means[s]['dd_mm']:.2f}\n({means[s]['dr_deg']:.2f},{means[s]['dp_deg']:.2f},{means[s]['dy_deg']:.2f})"
                for s in structures
            ]
        )
        fig, ax = plt.subplots(figsize=(2.0 * len(structures) + 1.5, 0.8 * len(text) + 1.2))
        ax.axis("off")
        tab = ax.table(
            cellText=text,
            colLabels=[s.replace("_", "\n", 1) for s in structures],
            rowLabels=[f"orient {o}" for o in orients] + ["mean |.|"],
            loc="center",
            cellLoc="center",
        )
        tab.auto_set_font_size(False)
        tab.set_fontsize(7)
        tab.scale(1.0, 2.6)
        ax.set_title("Teaching error: dd mm (dr, dp, dy deg)")
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=130, bbox_inches="tight", format="png")
        plt.close(fig)
        return path


class TeachingBreakdown(TeachingPrecision):
    """One factor at a time (``vary: name=value``): distance, marker size, frames, noise."""

    def summarize(self, rows: list[dict[str, Any]], out_dir: Path) -> list[Path]:
        """``breakdown.{csv,md,png}``: median and max errors per factor level."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        groups: dict[tuple[str, float], list[dict[str, Any]]] = {}
        for r in rows:
            vary = r.get("point", {}).get("vary", "baseline")
            name, _, value = vary.partition("=")
            groups.setdefault((name, float(value) if value else 0.0), []).append(r)
        recs = []
        for (name, value), rs in sorted(groups.items()):
            ms = [r["metrics"] for r in rs if r.get("ok")]
            ang = [max(abs(m["dr_deg"]), abs(m["dp_deg"]), abs(m["dy_deg"])) for m in ms]
            recs.append(
                {
                    "factor": name,
                    "value": value,
                    "trials": len(rs),
                    "ok": len(ms),
                    "dd_abs_median_mm": float(np.median([abs(m["dd_mm"]) for m in ms])) if ms else np.nan,
                    "dd_abs_max_mm": float(np.max([abs(m["dd_mm"]) for m in ms])) if ms else np.nan,
                    "angle_abs_median_deg": float(np.median(ang)) if ang else np.nan,
                    "angle_abs_max_deg": float(np.max(ang)) if ang else np.nan,
                    "v_a_err_median_deg": float(np.median([m["v_a_err_deg"] for m in ms])) if ms else np.nan,
                }
            )
        cols = list(recs[0]) if recs else []
        md = "# Teaching precision breakdown\n\n| " + " | ".join(cols) + " |\n|" + "---|" * len(cols) + "\n"
        md += "".join(
            "| " + " | ".join(f"{r[c]:.4g}" if isinstance(r[c], float) else str(r[c]) for c in cols) + " |\n"
            for r in recs
        )
        paths = [write_text(out_dir / "breakdown.md", md), write_text(out_dir / "breakdown.csv", to_csv(recs))]
        factors = [f for f in dict.fromkeys(r["factor"] for r in recs) if f != "baseline"]
        if factors:
            fig, axes = plt.subplots(1, len(factors), figsize=(4 * len(factors), 3.2), squeeze=False)
            for ax, f in zip(axes[0], factors, strict=True):
                rr = [r for r in recs if r["factor"] == f]
                x = [r["value"] for r in rr]
                ax.plot(x, [r["dd_abs_median_mm"] for r in rr], "o-", label="|dd| median, mm")
                ax.plot(x, [r["dd_abs_max_mm"] for r in rr], "o--", label="|dd| max, mm")
                ax.plot(x, [r["angle_abs_median_deg"] for r in rr], "s-", label="|angle| median, deg")
                ax.plot(x, [r["angle_abs_max_deg"] for r in rr], "s--", label="|angle| max, deg")
                ax.plot(x, [1.0 - r["ok"] / r["trials"] for r in rr], "k:", label="failure rate")
                ax.set_xlabel(f)
                ax.set_yscale("symlog", linthresh=0.1)
                ax.grid(alpha=0.3)
            axes[0][0].legend(fontsize=7)
            fig.tight_layout()
            with atomic_path(out_dir / "breakdown.png") as tmp:
                fig.savefig(tmp, dpi=120, format="png")
            plt.close(fig)
            paths.append(out_dir / "breakdown.png")
        return paths
