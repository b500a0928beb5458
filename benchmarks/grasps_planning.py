"""Grasp planning benchmark: distinct grasps and planning time per library part (cache excluded).

For every part of configs/parts/set1 and set2, the ``antipodal`` planner plans
for the Nextage gripper with the cache off, ``--repeats`` times after one
warm-up plan; the median wall time and CPU time (all threads of this process)
are reported with the number of distinct collision-free force-closure grasps.
Targets (issue 7): >= 40 distinct grasps per part, <= 1 s per part on 2 cores.
The machine's load average is printed, since other processes share the cores.

Run: .venv/bin/python benchmarks/grasps_planning.py [--repeats 3] [--pad-min-support 1.0] [--max-grasps N]
     [--out out/grasps_benchmark]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

from asmteach.core.errors import UserError
from asmteach.core.io import write_json, write_text
from asmteach.core.sweep import to_markdown
from asmteach.plugins.planners.grasps.commands import load_hand
from asmteach.plugins.planners.grasps.experiment import library_parts
from asmteach.plugins.planners.grasps.planner import AntipodalGraspPlanner

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--pad-min-support", type=float, default=None, help="override the planner's default")
    ap.add_argument("--max-grasps", type=int, default=None, help="override the planner's cap (default 300)")
    ap.add_argument("--out", default=str(REPO / "out" / "grasps_benchmark"))
    args = ap.parse_args()
    hand = load_hand("nextage")
    parts = library_parts([REPO / "configs/parts/set1", REPO / "configs/parts/set2"])
    settings = {"cache": False}
    if args.pad_min_support is not None:
        settings["pad_min_support"] = args.pad_min_support
    if args.max_grasps is not None:
        settings["max_grasps"] = args.max_grasps
    planner = AntipodalGraspPlanner(settings, seed=args.seed)
    planner.plan(next(iter(parts.values())), hand)  # warm-up: imports, Open3D and fcl first use
    rows = []
    load_before = os.getloadavg()[0]
    for name, part in parts.items():
        walls, cpus, n, note = [], [], 0, ""
        for _ in range(args.repeats):
            c0, t0 = time.process_time(), time.perf_counter()
            try:
                n = len(planner.plan(part, hand))
            except UserError as exc:  # an ungraspable part is a result (0 grasps), with its reason
                n, note = 0, str(exc)
                planner.last_stats = {}
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
        rows.append(
            {
                "part": name,
                "distinct_grasps": n,
                "wall_s_median": round(statistics.median(walls), 4),
                "cpu_s_median": round(statistics.median(cpus), 4),
                **{k: v for k, v in planner.last_stats.items() if k in ("pairs", "force_closure", "pads_supported")},
                "note": note,
            }
        )
        print(f"{name:18s} {n:4d} grasps  wall {statistics.median(walls):.3f} s  cpu {statistics.median(cpus):.3f} s")
    load_after = os.getloadavg()[0]
    worst_wall = max(r["wall_s_median"] for r in rows)
    fewest = min(r["distinct_grasps"] for r in rows)
    summary = (
        f"parts {len(rows)}; fewest distinct grasps {fewest} (target >= 40); slowest median wall "
        f"{worst_wall:.3f} s, slowest median CPU {max(r['cpu_s_median'] for r in rows):.3f} s (target <= 1 s); "
        f"cores {os.cpu_count()}; load average {load_before:.1f} -> {load_after:.1f}"
    )
    print(summary)
    out = Path(args.out)
    write_json(
        out / "grasps_planning.json",
        {"summary": summary, "settings": planner.settings.model_dump(mode="json"), "rows": rows},
    )
    write_text(out / "grasps_planning.md", f"# Grasp planning benchmark\n\n{summary}\n\n" + to_markdown(rows))
    print(f"wrote {out / 'grasps_planning.md'}")


if __name__ == "__main__":
    main()
