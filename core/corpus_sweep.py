"""The ``part_corpus`` experiment: every stage measured on every part of the corpus, as a user hands it to us.

One trial is one (part, stage). The part comes from :mod:`asmteach.core.corpus`
and is written as a millimetre STL with a few open edges
(:func:`~asmteach.core.corpus.write_cad_stl`), then loaded through the same
path a user's file takes (units, repair), so every figure includes what that
path does to a part. Stages:

``collision``
    the convex decomposition (:func:`asmteach.core.convex_pieces.decompose`):
    method, pieces, Hausdorff distance, protrusion and uncovered distance (mm; it passes when both
    ways are within 0.1 mm), volume error.
``placements``, ``grasps``, ``detection``
    measured by the plugin that owns the stage through the
    ``asmteach_measure_part`` hook (placements against a drop test, grasps
    that hold in simulation, detection on seeded scenes); a stage no
    installed plugin measures fails the trial with that reason.

``summarize`` writes ``part_corpus.md`` (one row per part, one column group
per stage, the targets of issue 22 checked) and ``part_corpus.png`` (each
stage's pass rate per part family).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Literal

from pydantic import Field

from asmteach.core.errors import UserError
from asmteach.core.io import write_text
from asmteach.core.models import StrictModel
from asmteach.core.sweep import Experiment

__all__ = ["PartCorpus", "PartCorpusParams", "passed"]

Stage = Literal["collision", "placements", "grasps", "detection"]


class PartCorpusParams(StrictModel):
    """One trial: a corpus part and the stage to measure on it."""

    part: str = Field(description="corpus part name, e.g. 'tube_1' or 'ff_duck' (asmteach.core.corpus)")
    stage: Stage = Field(description="the stage measured")
    corpus_seed: int = Field(0, description="seed of the corpus sizes (not the trial seed)")
    open_faces: int = Field(3, ge=0, description="triangles left out of the STL, as CAD exports do")
    scenes: int = Field(5, ge=1, description="detection: scenes per part")
    frames: int = Field(4, ge=1, le=30, description="detection: depth frames stacked per fixed view, as a run senses")
    close_looks: int = Field(
        2, ge=0, le=10, description="detection: wrist-camera looks at a pose the view leaves ambiguous, as a run"
    )
    max_protrusion_mm: float = Field(0.1, gt=0, description="collision: largest protrusion that passes, mm")
    max_uncovered_mm: float = Field(0.1, gt=0, description="collision: largest uncovered distance that passes, mm")


def passed(stage: str, metrics: dict[str, Any]) -> bool:
    """Whether a stage's metrics meet issue 22's target for one part."""
    if stage == "collision":
        # both ways: pieces outside the mesh close clearances, mesh outside the pieces lets bodies through
        return bool(
            metrics["protrusion_mm"] <= metrics["max_protrusion_mm"]
            and metrics.get("uncovered_mm", 0.0) <= metrics.get("max_uncovered_mm", float("inf"))
        )
    if stage == "placements":
        return bool(metrics["agree"])
    if stage == "grasps":
        return bool(metrics["holding"] >= 30) if metrics["fits_hand"] else bool(metrics["reason"])
    if stage == "detection":
        return bool(metrics["wrong_found"] == 0 and metrics["success"] >= metrics["scenes"])
    raise ValueError(f"unknown stage {stage!r}")


class PartCorpus(Experiment):
    """Collision, placements, grasps and detection per corpus part (see the module docstring)."""

    Params = PartCorpusParams

    def check(self, params: PartCorpusParams) -> None:
        """A corpus part name that names no part fails the sweep before its first trial (not every trial)."""
        from asmteach.core import corpus

        name = params.part
        if name.startswith("ff_"):
            known = any(corpus._free_form_name(rel) == name for rel in corpus.PYBULLET_MESHES)
        else:
            family, _, index = name.rpartition("_")
            known = family in corpus._CSG and index.isdigit()
        if not known:
            raise UserError(
                f"params.part: no corpus part {name!r}; give '<family>_<index>' (families: "
                f"{', '.join(corpus.FAMILIES)}) or 'ff_<mesh stem>'"
            )

    def run_trial(self, params: PartCorpusParams, seed: int, workdir: Path) -> dict[str, Any]:
        from asmteach.core.convex_pieces import decompose
        from asmteach.core.corpus import corpus_part, write_cad_stl
        from asmteach.core.hooks import make_plugin_manager
        from asmteach.core.models import PartSpec
        from asmteach.core.parts import build_part

        try:
            source = corpus_part(params.part, params.corpus_seed)
        except ValueError as exc:
            raise UserError(f"part: {exc}") from None
        stl = write_cad_stl(source.mesh, Path(workdir) / f"{params.part}.stl", open_faces=params.open_faces, seed=seed)
        part = build_part(PartSpec(name=params.part, mesh=str(stl), mesh_units="mm"))
        base: dict[str, Any] = {"part": params.part, "family": source.family, "stage": params.stage}
        t0 = time.perf_counter()
        if params.stage == "collision":
            dec = decompose(part, cache=False)
            metrics = {
                "method": dec.method,
                "pieces": len(dec.pieces),
                "hausdorff_mm": 1000.0 * dec.hausdorff,
                "protrusion_mm": 1000.0 * dec.protrusion,
                "uncovered_mm": 1000.0 * dec.uncovered,
                "volume_error_pct": 100.0 * dec.volume_error,
                "max_protrusion_mm": params.max_protrusion_mm,
                "max_uncovered_mm": params.max_uncovered_mm,
            }
        else:
            pm = make_plugin_manager(progress=False)
            options = {"scenes": params.scenes, "frames": params.frames, "close_looks": params.close_looks}
            metrics = pm.hook.asmteach_measure_part(
                part=part, stage=params.stage, seed=seed, workdir=Path(workdir), options=options
            )
            if metrics is None:
                raise UserError(f"no installed plugin measures the {params.stage!r} stage (asmteach_measure_part)")
        out = {**base, **metrics, "stage_seconds": time.perf_counter() - t0}
        out["passed"] = passed(params.stage, out)
        return out

    def summarize(self, rows: list[dict[str, Any]], out_dir: Path) -> list[Path]:
        ok = [r["metrics"] for r in rows if r.get("ok")]
        failed = [r for r in rows if not r.get("ok")]
        if not ok and not failed:
            return []
        by_part: dict[str, dict[str, dict[str, Any]]] = {}
        for m in ok:
            by_part.setdefault(m["part"], {})[m["stage"]] = m
        stages = ("collision", "placements", "grasps", "detection")
        header = "| part | family | " + " | ".join(stages) + " |\n|---|---|" + "---|" * len(stages) + "\n"
        body = []
        for name in sorted(by_part):
            cells = [_cell(s, by_part[name].get(s)) for s in stages]
            family = next(iter(by_part[name].values()))["family"]
            body.append(f"| {name} | {family} | " + " | ".join(cells) + " |")
        totals = []
        for s in stages:
            ms = [m for m in ok if m["stage"] == s]
            if ms:
                line = f"- **{s}**: {sum(m['passed'] for m in ms)}/{len(ms)} parts pass"
                if s == "detection":
                    ok_scenes, scenes = sum(m["success"] for m in ms), sum(m["scenes"] for m in ms)
                    line += (
                        f"; {ok_scenes}/{scenes} scenes found within 5 mm / 5 deg "
                        f"({100 * ok_scenes / max(scenes, 1):.1f} %), "
                        f"{sum(m['wrong_found'] for m in ms)} wrong poses reported as found"
                    )
                if s == "grasps":
                    fit = [m for m in ms if m["fits_hand"]]
                    line += f"; {sum(m['holding'] >= 30 for m in fit)}/{len(fit)} parts that fit the hand hold >= 30"
                totals.append(line)
        crashed = [
            f"- {r['point']}: {str(r.get('error', '')).splitlines()[0] if r.get('error') else 'failed'}" for r in failed
        ]
        md = (
            "# part_corpus\n\n"
            + "\n".join(totals)
            + "\n\n"
            + (("Trials that raised:\n\n" + "\n".join(crashed) + "\n\n") if crashed else "")
            + header
            + "\n".join(body)
            + "\n"
        )
        paths = [write_text(out_dir / "part_corpus.md", md)]
        paths.append(_plot(ok, stages, out_dir / "part_corpus.png"))
        return paths


def _cell(stage: str, m: dict[str, Any] | None) -> str:
    if m is None:
        return "-"
    mark = "ok" if m["passed"] else "**NO**"
    if stage == "collision":
        uncov = f" U {m['uncovered_mm']:.3f}" if "uncovered_mm" in m else ""
        return f"{mark} {m['method']} {m['pieces']}p H {m['hausdorff_mm']:.2f} P {m['protrusion_mm']:.3f}{uncov} mm"
    if stage == "placements":
        return f"{mark} {m['reported']} rep / {m['drop_rests']} drop, miss {m['missed']}, spur {m['spurious']}"
    if stage == "grasps":
        return f"{mark} {m['holding']}/{m['grasps']} hold" if m["fits_hand"] else f"{mark} {m['reason']}"
    return f"{mark} {m['success']}/{m['scenes']} ok, {m['wrong_found']} wrong"


def _plot(ok: list[dict[str, Any]], stages: tuple[str, ...], path: Path) -> Path:
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from asmteach.core.io import atomic_path

    families = sorted({m["family"] for m in ok})
    fig = Figure(figsize=(10, 4))
    ax = fig.add_subplot(111)
    width = 0.8 / len(stages)
    for i, s in enumerate(stages):
        rate = [
            np.mean([m["passed"] for m in ok if m["stage"] == s and m["family"] == f] or [np.nan]) for f in families
        ]
        ax.bar(np.arange(len(families)) + i * width, rate, width, label=s)
    ax.set_xticks(np.arange(len(families)) + 0.4 - width / 2, families, rotation=40, ha="right")
    ax.set_ylabel("parts that meet the target")
    ax.set_ylim(0, 1.05)
    ax.legend(ncol=4, fontsize=8)
    ax.set_title("part corpus: each stage's pass rate per family")
    fig.tight_layout()
    FigureCanvasAgg(fig)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    return path
