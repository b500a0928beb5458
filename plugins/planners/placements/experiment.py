"""Experiment ``placements_vs_trimesh``: our placements against ``trimesh.poses.compute_stable_poses``.

On every library part and on closed meshes shipped with pybullet_data, one
run computes both, side by side, and reports per mesh:

* which placements match (same resting normal within ``match_tol_deg``);
* every trimesh pose with probability >= ``min_probability`` that passes the
  stability test (checked independently with
  :func:`~.stability.evaluate_direction`, no facet clustering) and that we miss
  (target: none);
* our placements that fail the same independent test (target: none);
* why the rest differ: trimesh poses whose COM projection falls outside the
  support polygon or whose margin is below ``min_margin`` (trimesh tests each
  hull *triangle* on its own and has no margin), low trimesh probabilities;
* the time of both (best of ``repeats``, fresh meshes so no cached hull) and their ratio.
"""

from __future__ import annotations

import glob
import time
from pathlib import Path
from typing import Any

import numpy as np
import pybullet_data
import trimesh
from pydantic import Field

from asmteach.core.interfaces import PartModel
from asmteach.core.io import write_text
from asmteach.core.models import PartSpec, StrictModel
from asmteach.core.parts import build_part, load_structure
from asmteach.core.sweep import Experiment, to_csv, to_markdown
from asmteach.plugins.planners.placements.planner import plan_placements
from asmteach.plugins.planners.placements.stability import evaluate_direction

__all__ = ["PlacementsVsTrimesh", "compare_mesh"]


class _Params(StrictModel):
    structures: list[str] = Field(
        default_factory=lambda: ["../parts/set1/*.yaml", "../parts/set2/*.yaml"],
        description="globs of structure YAMLs (relative to the experiment file); both parts of each",
    )
    pybullet_meshes: list[str] = Field(
        default_factory=lambda: ["duck.obj", "teddy2_VHACD_CHs.obj", "lego/lego.obj"],
        description="meshes under pybullet_data.getDataPath(); append ':mm' for millimetre files",
    )
    min_probability: float = Field(0.05, ge=0.0, le=1.0)
    min_margin: float = Field(0.1, ge=0.0)
    match_tol_deg: float = Field(1.0, gt=0.0)
    repeats: int = Field(3, ge=1, le=20)


def _normals_ours(placements: list[Any]) -> np.ndarray:
    return np.array([p.T_table_part[:3, :3].T @ [0.0, 0.0, -1.0] for p in placements]).reshape(-1, 3)


def _best_time(fn: Any, repeats: int) -> tuple[float, Any]:
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def compare_mesh(
    name: str, source: str, part: PartModel, *, min_probability: float, min_margin: float, match_tol_deg: float,
    repeats: int,
) -> dict[str, Any]:
    """Compare both planners on one part; returns a flat record with lists of reasons."""
    V = np.array(part.mesh.vertices, dtype=float)
    F = np.array(part.mesh.faces)
    com = np.asarray(part.center_of_mass, dtype=float)

    def fresh() -> trimesh.Trimesh:
        return trimesh.Trimesh(V, F, process=False)

    t_ours, ours = _best_time(lambda: plan_placements(fresh(), com, min_margin=min_margin, name=name), repeats)
    t_core, _ = _best_time(
        lambda: plan_placements(fresh(), com, min_margin=min_margin, symmetry=False, name=name), repeats
    )
    t_tm, (tm_T, tm_p) = _best_time(lambda: trimesh.poses.compute_stable_poses(fresh(), center_mass=com), repeats)
    hull_v = np.array(ours.hull.vertices, dtype=float)
    n_ours = _normals_ours(ours.placements)
    n_tm = np.array([T[:3, :3].T @ [0.0, 0.0, -1.0] for T in tm_T]).reshape(-1, 3)
    cos_tol = np.cos(np.radians(match_tol_deg))
    sim = n_ours @ n_tm.T if len(n_ours) and len(n_tm) else np.zeros((len(n_ours), len(n_tm)))

    # Our placements, checked with the independent test.
    ours_unstable = []
    for p, n in zip(ours.placements, n_ours, strict=True):
        ev = evaluate_direction(hull_v, com, n)
        if ev.margin < min_margin - 1e-6:
            ours_unstable.append(f"#{p.id} d/h={ev.margin:.3f}")
    # trimesh's poses: matched, missed, or why not ours.
    matched = missed = tm_unstable = tm_marginal = 0
    reasons: list[str] = []
    prob_diff: list[float] = []
    for j, (n, p) in enumerate(zip(n_tm, tm_p, strict=True)):
        ev = evaluate_direction(hull_v, com, n)
        hit = np.flatnonzero(sim[:, j] >= cos_tol) if len(n_ours) else np.array([], dtype=int)
        if len(hit):
            matched += 1
            prob_diff.append(abs(float(p) - ours.placements[int(hit[0])].probability))
            continue
        if ev.margin < 0:
            tm_unstable += 1
            reasons.append(f"trimesh p={p:.3f}: COM outside support (d/h={ev.margin:.2f})")
        elif ev.margin < min_margin:
            tm_marginal += 1
            reasons.append(f"trimesh p={p:.3f}: margin d/h={ev.margin:.3f} < {min_margin}")
        elif p >= min_probability:
            missed += 1
            reasons.append(f"MISSED trimesh p={p:.3f} stable d/h={ev.margin:.3f}")
        else:
            reasons.append(f"trimesh p={p:.3f} < {min_probability}: stable d/h={ev.margin:.3f}, not ours")
    tm_p05_stable = sum(
        1 for n, p in zip(n_tm, tm_p, strict=True)
        if p >= min_probability and evaluate_direction(hull_v, com, n).margin >= min_margin
    )
    ours_only = [
        f"ours #{pl.id} p={pl.probability:.3f} absent from trimesh"
        for i, pl in enumerate(ours.placements)
        if not (len(n_tm) and np.any(sim[i] >= cos_tol))
    ]
    return {
        "mesh": name,
        "source": source,
        "faces": len(F),
        "hull_faces": len(ours.hull.faces),
        "ours": len(ours.placements),
        "trimesh": len(tm_p),
        "trimesh_p05_stable": tm_p05_stable,
        "matched": matched,
        "missed": missed,
        "ours_unstable": len(ours_unstable),
        "trimesh_com_outside": tm_unstable,
        "trimesh_below_margin": tm_marginal,
        "ours_only": len(ours_only),
        "max_prob_diff": max(prob_diff) if prob_diff else 0.0,
        "ms_ours": t_ours * 1000.0,
        "ms_ours_no_symmetry": t_core * 1000.0,
        "ms_trimesh": t_tm * 1000.0,
        "speedup": t_tm / t_ours,
        "why": "; ".join(reasons + ours_only + [f"ours unstable {u}" for u in ours_unstable]),
    }


class PlacementsVsTrimesh(Experiment):
    """Placements and timing of ours vs trimesh's ``compute_stable_poses`` (see the module docstring)."""

    Params = _Params

    def _meshes(self, params: _Params) -> list[tuple[str, str, PartModel]]:
        out: list[tuple[str, str, PartModel]] = []
        for pattern in params.structures:
            for f in sorted(glob.glob(str(self.path(pattern)))):
                task = load_structure(f)
                for spec in (task.part_a, task.part_b):
                    out.append((spec.name, Path(f).name, build_part(spec, Path(f).parent)))
        root = Path(pybullet_data.getDataPath())
        for entry in params.pybullet_meshes:
            rel, _, units = entry.partition(":")
            spec = PartSpec(name=Path(rel).stem, mesh=str(root / rel), mesh_units=units or "m")
            out.append((spec.name, f"pybullet_data/{rel}", build_part(spec)))
        return out

    def run_trial(self, params: Any, seed: int, workdir: Path) -> dict[str, Any]:
        """Compare on every mesh; per-mesh records go to ``workdir/meshes.csv`` and the row's ``meshes``."""
        records = [
            compare_mesh(
                name, source, part,
                min_probability=params.min_probability, min_margin=params.min_margin,
                match_tol_deg=params.match_tol_deg, repeats=params.repeats,
            )
            for name, source, part in self._meshes(params)
        ]
        write_text(workdir / "meshes.csv", to_csv(records))
        t_ours = sum(r["ms_ours"] for r in records)
        t_tm = sum(r["ms_trimesh"] for r in records)
        return {
            "meshes_compared": len(records),
            "missed_total": sum(r["missed"] for r in records),
            "ours_unstable_total": sum(r["ours_unstable"] for r in records),
            "trimesh_com_outside_total": sum(r["trimesh_com_outside"] for r in records),
            "trimesh_below_margin_total": sum(r["trimesh_below_margin"] for r in records),
            "ms_ours_total": t_ours,
            "ms_trimesh_total": t_tm,
            "speedup_total": t_tm / t_ours,
            "speedup_median": float(np.median([r["speedup"] for r in records])),
            "meshes": records,
        }

    def summarize(self, rows: list[dict[str, Any]], out_dir: Path) -> list[Path]:
        """``placements_vs_trimesh.md`` and ``.csv``: one line per mesh, totals and the target checks."""
        records = [m for r in rows if r.get("ok") for m in r["metrics"].get("meshes", [])]
        if not records:
            return []
        cols = [
            "mesh", "source", "faces", "ours", "trimesh", "trimesh_p05_stable", "matched", "missed",
            "ours_unstable", "trimesh_com_outside", "trimesh_below_margin", "ours_only", "max_prob_diff",
            "ms_ours", "ms_trimesh", "speedup",
        ]
        t_ours = sum(r["ms_ours"] for r in records)
        t_core = sum(r["ms_ours_no_symmetry"] for r in records)
        t_tm = sum(r["ms_trimesh"] for r in records)
        missed = sum(r["missed"] for r in records)
        unstable = sum(r["ours_unstable"] for r in records)
        md = [
            "# Stable placements: ours vs trimesh.poses.compute_stable_poses\n",
            f"{len(records)} meshes, one run, best of repeats. Total time: ours {t_ours:.1f} ms "
            f"(without symmetry detection {t_core:.1f} ms), trimesh {t_tm:.1f} ms: "
            f"**trimesh / ours = {t_tm / t_ours:.2f}x** (without symmetry {t_tm / t_core:.2f}x).\n",
            f"- trimesh placements with p >= 0.05 passing the stability test that we miss: **{missed}** (target 0)",
            f"- our placements failing the independent stability test: **{unstable}** (target 0)",
            f"- trimesh poses with the COM outside the support polygon: "
            f"{sum(r['trimesh_com_outside'] for r in records)}; below the margin: "
            f"{sum(r['trimesh_below_margin'] for r in records)}\n",
            to_markdown(records, cols),
            "\n## Why they differ\n",
        ]
        md += [f"- **{r['mesh']}**: {r['why']}" for r in records if r["why"]]
        return [
            write_text(out_dir / "placements_vs_trimesh.md", "\n".join(md) + "\n"),
            write_text(out_dir / "placements_vs_trimesh.csv", to_csv(records)),
        ]
