"""Grasps on any part: plan antipodal grasps for every part of the corpus and hold-test them in PyBullet.

For every part of :func:`asmteach.core.corpus.part_corpus` (seed ``--seed``), the ``antipodal`` planner
plans grasps for the Nextage gripper (cache off); then the kept grasps are hold-tested one by one in
:class:`~asmteach.plugins.planners.grasps.hold_check.HoldSimulator` (close, lift 10 cm, hold 2 s under a
shake), in an order spread evenly over the kept list (best, worst, middle, ...), until ``--target`` of
them held or ``--max-trials`` were run. A part gets its planner's reason when it has no grasp.

The part's mass is ``--density`` (kg/m^3; default 700, a hardwood block, as the part library has it)
times its volume; its centre of mass is the mesh's. The hold test simulates parts under 20 g at 20 g
(``HoldSimulator.min_part_mass``: Bullet lets 40 N fingers close through a gram-light part), which only
makes holding harder; the planner plans with the true mass. Pad-part friction is ``--friction`` (0.5,
the simulator's default); the planner assumes mu = 0.3.

Printed per part: candidates (contact pairs in force closure x palm orientations), grasps kept, grasps
tried, grasps that held, and the reason for none. The CSV goes to ``benchmarks/out/grasps_corpus.csv``.
Acceptance (issue 22): every part that fits the hand's opening has >= 30 grasps that hold.

Run: .venv/bin/python benchmarks/grasps_corpus.py [--seed 0] [--target 30] [--max-trials 45]
     [--parts wheel_0,tube_1] [--no-hold]
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np

from asmteach.core.corpus import part_corpus
from asmteach.core.errors import UserError
from asmteach.core.interfaces import PartModel
from asmteach.core.models import PartSpec
from asmteach.core.parts import mesh_hash
from asmteach.plugins.planners.grasps.commands import load_hand
from asmteach.plugins.planners.grasps.hold_check import HoldSimulator
from asmteach.plugins.planners.grasps.planner import AntipodalGraspPlanner

REPO = Path(__file__).resolve().parents[1]


def spread_order(n: int) -> list[int]:
    """``0..n-1`` in an order that spreads over the list: first, last, middle, then the midpoints between."""
    if n <= 0:
        return []
    order, seen = [], set()
    step = n
    while len(order) < n:
        for i in range(0, n, max(step, 1)):
            if i not in seen:
                seen.add(i)
                order.append(i)
        if n - 1 not in seen:
            seen.add(n - 1)
            order.append(n - 1)
        step //= 2
        if step == 0:
            order += [i for i in range(n) if i not in seen]
            break
    return order


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=0, help="corpus seed (and planner seed)")
    ap.add_argument("--target", type=int, default=30, help="stop hold-testing a part after this many held")
    ap.add_argument("--max-trials", type=int, default=45, help="hold-test at most this many grasps per part")
    ap.add_argument("--density", type=float, default=700.0, help="kg/m^3")
    ap.add_argument("--friction", type=float, default=0.5, help="pad-part friction in the hold test")
    ap.add_argument("--parts", default="", help="comma-separated part names (default: the whole corpus)")
    ap.add_argument("--no-hold", action="store_true", help="plan only")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "out" / "grasps_corpus.csv"))
    args = ap.parse_args()
    hand = load_hand("nextage")
    wanted = {p for p in args.parts.split(",") if p}
    corpus = [c for c in part_corpus(seed=args.seed) if not wanted or c.name in wanted]
    planner = AntipodalGraspPlanner({"cache": False}, seed=args.seed)
    rows = []
    print(f"{'part':22s} {'family':11s} {'cand':>6s} {'kept':>5s} {'tried':>5s} {'held':>5s}  plan_s  reason")
    for c in corpus:
        mesh = c.mesh
        part = PartModel(
            spec=PartSpec(name=c.name, mesh=f"{c.name}.stl"),
            mesh=mesh,
            mass=float(args.density * mesh.volume),
            center_of_mass=np.asarray(mesh.center_mass, dtype=float),
            source_hash=mesh_hash(mesh),
        )
        t0 = time.perf_counter()
        reason = ""
        try:
            grasps = planner.plan(part, hand)
        except UserError as exc:  # an ungraspable part is a result, with its reason
            grasps, reason = [], str(exc)
        plan_s = time.perf_counter() - t0
        stats = planner.last_stats  # filled in up to the stage that refused the part
        tried = held = 0
        fails: dict[str, int] = {}
        if grasps and not args.no_hold:
            with HoldSimulator(hand, part, friction=args.friction) as sim:
                for i in spread_order(len(grasps)):
                    if held >= args.target or tried >= args.max_trials:
                        break
                    r = sim.check(grasps[i])
                    tried += 1
                    held += int(r.held)
                    if not r.held:
                        fails[r.reason] = fails.get(r.reason, 0) + 1
        row = {
            "part": c.name,
            "family": c.family,
            "extents_mm": "x".join(f"{e * 1000:.0f}" for e in mesh.extents),
            "mass_kg": round(part.mass, 4),
            "candidates": stats.get("candidates", ""),
            "contact_ok": stats.get("pads_supported", ""),
            "kept": len(grasps),
            "tried": tried,
            "held": held,
            "hold_failures": "; ".join(f"{k}: {v}" for k, v in sorted(fails.items())),
            "plan_s": round(plan_s, 2),
            "reason": reason,
        }
        rows.append(row)
        print(
            f"{c.name:22s} {c.family:11s} {row['candidates']!s:>6s} {len(grasps):5d} {tried:5d} {held:5d}  "
            f"{plan_s:6.2f}  {reason}",
            flush=True,
        )
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    planned = [r for r in rows if r["kept"] > 0]
    ok = [r for r in planned if r["held"] >= args.target]
    print(
        f"parts {len(rows)}; with grasps {len(planned)}; with >= {args.target} holding grasps {len(ok)}"
        + ("" if args.no_hold else f" (of {len(planned)} planned)")
        + f"; no grasp: {len(rows) - len(planned)}; wrote {out}"
    )


if __name__ == "__main__":
    main()
