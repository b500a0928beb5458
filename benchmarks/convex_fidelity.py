"""Convex decomposition fidelity on any part: the pieces PyBullet collides, against the part's mesh.

For every part of :func:`asmteach.core.corpus.part_corpus` (seed ``--seed``), taken as a mesh part (the
mesh route of :func:`asmteach.core.convex_pieces.decompose`, no parametric solid), prints the route taken
(``convex``, ``plane_split`` or ``coacd``), the piece count, the two-sided Hausdorff distance between
the pieces' union and the mesh as solids (mm; the larger of the next two), the largest protrusion of a
piece outside the mesh (mm; what closes a clearance), the largest distance of the mesh, surface and inside,
from the pieces (mm, "uncov"; where a body would pass through), the union's volume error (%) and the time
(s). The cache is off, so every part is built. The CSV goes to ``benchmarks/out/convex_fidelity.csv``;
the last lines give the median and max per route.

Run: .venv/bin/python benchmarks/convex_fidelity.py [--seed 0] [--parts prism_hole_0,ff_duck]
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

from asmteach.core.convex_pieces import DecompositionSettings, decompose
from asmteach.core.corpus import part_corpus
from asmteach.core.interfaces import PartModel
from asmteach.core.models import PartSpec
from asmteach.core.parts import mesh_hash

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--parts", default="", help="comma-separated part names (default: the whole corpus)")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "out" / "convex_fidelity.csv"))
    args = ap.parse_args()
    wanted = {p for p in args.parts.split(",") if p}
    settings = DecompositionSettings(seed=args.seed)
    rows = []
    print(
        f"{'part':22s} {'family':11s} {'method':11s} {'pieces':>6s} {'haus_mm':>8s} {'prot_mm':>8s} "
        f"{'uncov_mm':>8s} {'vol_%':>7s} {'s':>6s}"
    )
    for cp in part_corpus(seed=args.seed):
        if wanted and cp.name not in wanted:
            continue
        part = PartModel(
            spec=PartSpec(name=cp.name, mesh=f"{cp.name}.stl"),
            mesh=cp.mesh,
            mass=700.0 * float(cp.mesh.volume),
            center_of_mass=np.asarray(cp.mesh.center_mass),
            source_hash=mesh_hash(cp.mesh),
        )
        d = decompose(part, settings, cache=False)
        row = {
            "part": cp.name,
            "family": cp.family,
            "method": d.method,
            "pieces": len(d.pieces),
            "hausdorff_mm": round(1e3 * d.hausdorff, 4),
            "protrusion_mm": round(1e3 * d.protrusion, 4),
            "uncovered_mm": round(1e3 * d.uncovered, 4),
            "volume_error_pct": round(100 * d.volume_error, 3),
            "seconds": round(d.seconds, 2),
        }
        rows.append(row)
        print(
            f"{cp.name:22s} {cp.family:11s} {d.method:11s} {len(d.pieces):6d} {row['hausdorff_mm']:8.4f} "
            f"{row['protrusion_mm']:8.4f} {row['uncovered_mm']:8.4f} {row['volume_error_pct']:7.3f} "
            f"{row['seconds']:6.1f}",
            flush=True,
        )
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"\nwrote {out}")
    for method in [*sorted({r["method"] for r in rows}), "all"]:
        sel = [r for r in rows if method in ("all", r["method"])]
        cols = ("pieces", "hausdorff_mm", "protrusion_mm", "uncovered_mm", "volume_error_pct", "seconds")
        stats = "  ".join(f"{c} {np.median([r[c] for r in sel]):.4g}/{np.max([r[c] for r in sel]):.4g}" for c in cols)
        print(f"{method:11s} n={len(sel):2d}  median/max: {stats}")


if __name__ == "__main__":
    main()
