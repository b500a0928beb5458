"""Stable placements against a PyBullet drop test over the part corpus (issue 22, deliverable 3).

For every part of ``asmteach.core.corpus.part_corpus(seed)`` the placements
planner reports its placements; ``drop_test`` drops the part from ``--drops``
seeded random orientations onto a plane, releases each reported placement with
tilts of 4.6 degrees (0.8 atan 0.1) about 8 axes, let down quasi-statically,, and compares (see
``plugins/planners/placements/drop_test.py``).
Columns: reported placements, rests found by dropping, matched, missed (a rest
on no reported placement nor a facet the rule refuses on purpose), below margin
(a rest on a facet that holds the COM with d/h < 0.1, which the rule refuses),
fragile (of those, the ones a tilt of 6.9 degrees = 1.2 atan 0.1 about one of 8 axes knocks the part
out of), spurious (a released placement that toppled away), rolled (a released placement
on a curved side that rolled along it, the COM height kept within 5 %), unsettled drops.

``--cad`` goes through what a user sends: the part written as a millimetre STL
with 3 faces removed (``write_cad_stl``) and read back with ``build_part``
(placements then come from the convex hull of an open mesh).

Run: .venv/bin/python benchmarks/placements_drop.py [--seed 0] [--drops 30] [--cad] [--only NAME ...]
Writes benchmarks/out/placements_drop[_cad]_seed<seed>.csv.
"""

from __future__ import annotations

import argparse
import csv
import tempfile
import time
from pathlib import Path

import numpy as np

from asmteach.core.corpus import part_corpus, write_cad_stl
from asmteach.core.parts import PartSpec, build_part
from asmteach.plugins.planners.placements.drop_test import down_normal, drop_test
from asmteach.plugins.planners.placements.planner import plan_placements

OUT = Path(__file__).resolve().parent / "out"
COLUMNS = ["part", "family", "reported", "rests", "matched", "missed", "below_margin", "fragile", "spurious", "rolled",
           "unsettled", "plan_s", "drop_s"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0, help="corpus seed")
    ap.add_argument("--drops", type=int, default=30, help="random drops per part")
    ap.add_argument("--cad", action="store_true", help="go through a millimetre STL with open edges")
    ap.add_argument("--only", nargs="*", default=None, help="part names to run (default: all)")
    args = ap.parse_args()

    rows: list[dict[str, object]] = []
    print(" ".join(f"{c:>12}" if i else f"{c:<22}" for i, c in enumerate(COLUMNS)))
    with tempfile.TemporaryDirectory() as tmp:
        for part in part_corpus(seed=args.seed):
            if args.only and part.name not in args.only:
                continue
            mesh, com = part.mesh, None
            if args.cad:
                path = write_cad_stl(part.mesh, Path(tmp) / f"{part.name}.stl", seed=args.seed)
                model = build_part(PartSpec(name=part.name, mesh=str(path), mesh_units="mm"), Path(tmp))
                mesh, com = model.mesh, model.center_of_mass
            t0 = time.perf_counter()
            res = plan_placements(mesh, com, name=part.name)
            t1 = time.perf_counter()
            normals = np.array([down_normal(p.T_table_part) for p in res.placements]).reshape(-1, 3)
            refused = np.array([r.normal for r in res.rejected]).reshape(-1, 3)
            rep = drop_test(mesh, normals, res.center_of_mass, refused_normals=refused, drops=args.drops,
                            seed=args.seed)
            t2 = time.perf_counter()
            row: dict[str, object] = dict(
                part=part.name, family=part.family, reported=rep.reported, rests=rep.found, matched=rep.matched,
                missed=rep.missed, below_margin=rep.below_margin, fragile=rep.below_margin_fragile,
                spurious=rep.spurious, rolled=rep.rolled_away,
                unsettled=rep.unsettled, plan_s=round(t1 - t0, 3), drop_s=round(t2 - t1, 2),
            )
            rows.append(row)
            print(" ".join(f"{row[c]!s:>12}" if i else f"{row[c]!s:<22}" for i, c in enumerate(COLUMNS)), flush=True)
    agree = sum(1 for r in rows if r["missed"] == 0 and r["spurious"] == 0)
    tot = {c: sum(int(r[c]) for r in rows) for c in COLUMNS[2:11]}
    print(f"\n{len(rows)} parts; agreement (no missed rest, no spurious placement) on {agree}/{len(rows)}; totals: "
          + ", ".join(f"{k} {v}" for k, v in tot.items()))
    OUT.mkdir(parents=True, exist_ok=True)
    out = OUT / f"placements_drop{'_cad' if args.cad else ''}_seed{args.seed}.csv"
    with out.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS)
        w.writeheader()
        w.writerows(rows)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
