"""Motion planner benchmark: T-RRT (BiTRRT) against RRTConnect on the 6-D toy problem.

The problem (``toyworld.clutter6d``): joints in [-pi, pi], a wall across joint 0
with a 2.5 rad square hole, a ball and a box, obstacles padded by 0.02 rad,
motions checked every 0.02 rad; the straight line start -> goal is blocked.
Each planner runs ``--trials`` queries with seeds 0..n-1 and the inverse
clearance cost map ``1 / max(clearance, 1e-3)``. Both planners get the same
callables, which carry vectorised twins (``.batch``, see
``plugins/planners/motion/batch.py``): T-RRT uses them for whole-edge checks
and its shortener, RRTConnect (OMPL) calls them one state at a time. The row
``trrt_1by1`` runs T-RRT on plain callables (OMPL motion checks and simplifier)
for comparison. Reported per planner: success rate, median / 90th percentile
total time per query (s, planning plus simplification), median path length
(rad), median mean and maximum path cost (1 / clearance along the path every
0.01 rad; lower is safer), and the minimum clearance (rad) to the unpadded
obstacles. Writes ``motion_planners.json`` and ``motion_planners.png``.

Run: .venv/bin/python benchmarks/motion_planners.py [--trials 100] [--time-limit 10] [--out DIR] [--no-cost]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from asmteach.core.io import atomic_path, write_json
from asmteach.core.trajectory.batch import batched, inverse_clearance_cost
from asmteach.core.trajectory.interpolate import densify
from asmteach.plugins.planners.motion.ompl_planners import RRTConnectPlanner
from asmteach.plugins.planners.motion.toyworld import JointWorld, clutter6d
from asmteach.plugins.planners.motion.trrt import TRRTPlanner


def run(
    planner_cls: type, trials: int, time_limit: float, use_cost: bool = True, vectorised: bool = True
) -> list[dict]:
    world, start, goal = clutter6d(margin=0.02)
    exact = JointWorld(world.lower, world.upper, world.obstacles, margin=0.0)
    if vectorised:
        is_valid = batched(world.is_valid, world.valid_batch)
        cost = inverse_clearance_cost(batched(world.clearance, world.clearance_batch))
    else:
        is_valid, cost = world.is_valid, inverse_clearance_cost(world.clearance)
    rows = []
    for seed in range(trials):
        planner = planner_cls({"collision_resolution": 0.02}, seed=seed)
        t0 = time.perf_counter()
        res = planner.plan(
            start,
            goal,
            lower=world.lower,
            upper=world.upper,
            is_valid=is_valid,
            cost=cost if use_cost else None,
            time_limit=time_limit,
        )
        row = {"seed": seed, "success": res.success, "time": time.perf_counter() - t0, "reason": res.reason}
        if res.success:
            dense = densify(res.path, 0.01)
            clearance = exact.clearance_batch(dense)
            costs = 1.0 / np.maximum(world.clearance_batch(dense), 1e-3)
            row.update(
                length=float(np.sum(np.linalg.norm(np.diff(res.path, axis=0), axis=1))),
                mean_cost=float(costs.mean()),
                max_cost=float(costs.max()),
                min_clearance=float(clearance.min()),
                valid=bool(np.all(exact.valid_batch(dense))),
            )
        rows.append(row)
    return rows


def summarize(rows: list[dict]) -> dict:
    ok = [r for r in rows if r["success"]]
    times = np.array([r["time"] for r in rows])

    def med(key: str) -> float:
        return float(np.median([r[key] for r in ok])) if ok else float("nan")

    return {
        "trials": len(rows),
        "success_rate": len(ok) / len(rows),
        "median_time_s": float(np.median(times)),
        "p90_time_s": float(np.percentile(times, 90)),
        "median_length_rad": med("length"),
        "median_mean_cost": med("mean_cost"),
        "median_max_cost": med("max_cost"),
        "min_clearance_rad": float(min(r["min_clearance"] for r in ok)) if ok else float("nan"),
        "all_paths_valid": all(r["valid"] for r in ok),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--time-limit", type=float, default=10.0)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/out"))
    ap.add_argument(
        "--no-cost", action="store_true", help="plan without the cost map (T-RRT becomes a goal-biased RRT)"
    )
    args = ap.parse_args()
    results = {}
    for name, cls, vectorised in (
        ("trrt", TRRTPlanner, True),
        ("trrt_1by1", TRRTPlanner, False),
        ("rrtconnect", RRTConnectPlanner, True),
    ):
        rows = run(cls, args.trials, args.time_limit, use_cost=not args.no_cost, vectorised=vectorised)
        results[name] = {"summary": summarize(rows), "rows": rows}
        s = results[name]["summary"]
        print(
            f"{name:10s} success {s['success_rate']:.0%}  median time {s['median_time_s']:.2f} s "
            f"(p90 {s['p90_time_s']:.2f})  length {s['median_length_rad']:.2f} rad  "
            f"mean cost {s['median_mean_cost']:.2f}  max cost {s['median_max_cost']:.2f}  "
            f"min clearance {s['min_clearance_rad']:.3f} rad  valid {s['all_paths_valid']}",
            flush=True,
        )
    args.out.mkdir(parents=True, exist_ok=True)
    write_json(args.out / "motion_planners.json", results)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.5))
    names = list(results)
    axes[0].boxplot([[r["time"] for r in results[n]["rows"]] for n in names], tick_labels=names)
    axes[0].set_ylabel("planning time (s)")
    axes[1].boxplot([[r["mean_cost"] for r in results[n]["rows"] if r["success"]] for n in names], tick_labels=names)
    axes[1].set_ylabel("mean path cost (1 / clearance)")
    fig.suptitle(f"6-D toy problem, {args.trials} seeds")
    fig.tight_layout()
    with atomic_path(args.out / "motion_planners.png") as tmp:
        fig.savefig(tmp, format="png", dpi=120)
    print(f"wrote {args.out / 'motion_planners.json'} and {args.out / 'motion_planners.png'}")


if __name__ == "__main__":
    main()
