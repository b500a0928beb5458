"""Cycle time: the old rest-to-rest timing against the blended time-optimal one, paired on the same plans.

For each seed the demo pipeline runs once (teach, spawn, detect, grasps, plan;
with ``--execute K`` the first K seeds also execute and measure). When the
assembly planner times its plan (``to_plan``), the benchmark takes the same
untimed steps and times them both ways in this process: ``trapezoid`` (one
rest-to-rest trapezoid per waypoint pair, the old timing) and ``toppra`` (the
default), recording the robot seconds (simulated motion time) by kind of
motion, the computer seconds each timing took, and the worst velocity and
acceleration of every sample against the limits (chord slopes and second
differences of the samples the robot is sent, per joint, as a fraction of its
limit; 1.0 is at the limit). The plan the pipeline goes on with is the toppra
one, and the pipeline's independent PyBullet re-check of that plan (5 mm
sweeps, ``execution.recheck_plan``) gives the collisions column.

Printed per seed and as medians: robot seconds old / new and their ratio,
robot seconds per kind, computer seconds per stage. Rows go to
``OUT/cycle_time.jsonl`` (one per seed), run folders to ``OUT/seed_N``.

``--go-on trapezoid`` executes (and re-checks) the old timing's plan instead, to pair the assembly outcome.

Run: .venv/bin/python benchmarks/cycle_time.py [--seeds 20] [--first-seed 1] [--execute 3] [--go-on toppra]
[--out DIR]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from asmteach.core import pipeline
from asmteach.core.config import load_run_config
from asmteach.core.errors import UserError
from asmteach.core.pipeline import run as pipeline_run
from asmteach.plugins.planners.regrasp import planner as regrasp_planner
from asmteach.plugins.planners.regrasp.plan_io import KINDS, to_plan

ROOT = Path(__file__).resolve().parents[1]
TIMINGS = ("trapezoid", "toppra")


def _limit_ratios(plan: Any, robot: Any, acceleration: float) -> tuple[float, float]:
    """Worst ``|chord velocity| / v_max`` and ``|second difference| / a_max`` over every sample of every motion."""
    worst_v = worst_a = 0.0
    for seg in plan.segments:
        if seg.trajectory is None or len(seg.trajectory.times) < 2:
            continue
        t = np.asarray(seg.trajectory.times, float)
        q = np.asarray(seg.trajectory.positions, float)
        dt = np.diff(t)
        ok = dt > 0
        v = np.diff(q, axis=0)[ok] / dt[ok, None]
        worst_v = max(worst_v, float(np.max(np.abs(v) / robot.speed_limits(seg.trajectory.arm))))
        if len(v) > 1:
            mid = 0.5 * (dt[ok][1:] + dt[ok][:-1])
            a = np.diff(v, axis=0) / mid[:, None]
            worst_a = max(worst_a, float(np.max(np.abs(a)) / acceleration))
    return worst_v, worst_a


class _Pairing:
    """Wraps the assembly planner's ``to_plan``: the same steps timed both ways; the toppra plan goes on."""

    def __init__(self, go_on: str = "toppra") -> None:
        self.calls: list[dict[str, Any]] = []
        self.go_on = go_on  # the timing of the plan the pipeline goes on with

    def __call__(self, steps: Any, robot: Any, acceleration: float, **kw: Any) -> Any:
        row: dict[str, Any] = {}
        plans = {}
        kw.pop("timing", None)  # the planner's own choice; the benchmark times the steps both ways
        for timing in TIMINGS:
            t0 = time.perf_counter()
            plans[timing] = to_plan(steps, robot, acceleration, timing=timing, **kw)
            row[f"{timing}_timing_s"] = time.perf_counter() - t0
            row[f"{timing}_robot"] = plans[timing].stats["robot_seconds"]
            row[f"{timing}_max_v"], row[f"{timing}_max_a"] = _limit_ratios(plans[timing], robot, acceleration)
        row["blends"] = plans["toppra"].stats.get("blends")
        self.calls.append(row)
        return plans[self.go_on]


def _plan_only(*_: Any, **__: Any) -> Any:
    raise pipeline.StageFailed("not executed (the benchmark only plans this seed)")


def run_seed(config: Path, seed: int, out: Path, execute: bool, go_on: str = "toppra") -> dict[str, Any]:
    """One seed: the pipeline with the pairing in place (``go_on``: the timing executed); returns the row."""
    pairing = _Pairing(go_on)
    original_to_plan, original_execute = regrasp_planner.to_plan, pipeline_run.execute_stage
    regrasp_planner.to_plan = pairing
    if not execute:
        pipeline_run.execute_stage = _plan_only
    try:
        cfg = load_run_config(config, overrides={"seed": seed, "execution.animation": False})
        report = pipeline.run_pipeline(cfg, out / f"seed_{seed}")
    finally:
        regrasp_planner.to_plan, pipeline_run.execute_stage = original_to_plan, original_execute
    row: dict[str, Any] = {
        "seed": seed,
        "executed": execute,
        "go_on": go_on,
        "success": bool(report.success),
        "failed_stage": report.failed_stage or "",
        "reason": (report.reason or "")[:160],
        "computer_s": dict(report.computer_seconds),
        "robot_executed": dict(report.robot_seconds),
        "recheck_collisions": report.metrics.get("plan_recheck_collisions"),
        "timings": len(pairing.calls),
    }
    if pairing.calls:
        row.update(pairing.calls[0])  # the plan stage's plan (look_again may time a second one)
    return row


def _median(values: list[float]) -> float:
    return float(statistics.median(values)) if values else float("nan")


def report(rows: list[dict[str, Any]]) -> str:
    """Per-seed lines and medians, as printed."""
    planned = [r for r in rows if "toppra_robot" in r and r["failed_stage"] != "plan"]
    lines = [
        "seed  plan  robot s old -> new (ratio)   transit  approach insert  regrasp   max v/lim old new"
        "  max a/lim old new  recheck  computer s plan (timing ms old/new)  result"
    ]
    for r in rows:
        if "toppra_robot" not in r:
            lines.append(f"{r['seed']:4d}  no plan: {r['failed_stage']} {r['reason'][:80]}")
            continue
        old, new = r["trapezoid_robot"], r["toppra_robot"]
        kinds = "  ".join(f"{old[k]:5.1f}/{new[k]:5.1f}" for k in KINDS)
        result = ("SUCCESS" if r["success"] else f"FAILED at {r['failed_stage']}") if r["executed"] else "planned"
        lines.append(
            f"{r['seed']:4d}  ok    {old['total']:7.1f} -> {new['total']:6.1f} ({old['total'] / new['total']:4.2f}x)  "
            f"{kinds}   {r['trapezoid_max_v']:.3f} {r['toppra_max_v']:.3f}   {r['trapezoid_max_a']:.3f} "
            f"{r['toppra_max_a']:.3f}   {r['recheck_collisions']!s:>4}   {r['computer_s'].get('plan', 0):6.1f} "
            f"({1000 * r['trapezoid_timing_s']:.0f}/{1000 * r['toppra_timing_s']:.0f})  {result}"
        )
    if planned:
        old = [r["trapezoid_robot"]["total"] for r in planned]
        new = [r["toppra_robot"]["total"] for r in planned]
        lines.append("")
        lines.append(f"plans: {len(planned)} of {len(rows)} seeds")
        lines.append(
            f"median robot seconds: trapezoid {_median(old):.1f} s, toppra {_median(new):.1f} s; "
            f"median ratio {_median([a / b for a, b in zip(old, new, strict=True)]):.2f}x "
            f"(min {min(a / b for a, b in zip(old, new, strict=True)):.2f}x)"
        )
        for k in KINDS:
            lines.append(
                f"  {k:9s} trapezoid {_median([r['trapezoid_robot'][k] for r in planned]):6.1f} s  "
                f"toppra {_median([r['toppra_robot'][k] for r in planned]):6.1f} s"
            )
        lines.append(
            f"worst sample over all plans: velocity {max(r['toppra_max_v'] for r in planned):.4f} of its "
            f"limit (trapezoid {max(r['trapezoid_max_v'] for r in planned):.4f}), acceleration "
            f"{max(r['toppra_max_a'] for r in planned):.4f} (trapezoid "
            f"{max(r['trapezoid_max_a'] for r in planned):.4f})"
        )
        lines.append(
            f"re-check collisions of the toppra plans (PyBullet, 5 mm sweeps): "
            f"{sum(int(r['recheck_collisions'] or 0) for r in planned)} in {len(planned)} plans"
        )
        lines.append(
            f"median computer seconds timing a plan: trapezoid "
            f"{_median([r['trapezoid_timing_s'] for r in planned]):.3f} s, toppra "
            f"{_median([r['toppra_timing_s'] for r in planned]):.3f} s"
        )
        stages: dict[str, list[float]] = {}
        for r in rows:
            for stage, s in r["computer_s"].items():
                stages.setdefault(stage, []).append(s)
        lines.append(
            "median computer seconds per stage: "
            + ", ".join(f"{k} {_median(v):.1f} (n={len(v)})" for k, v in stages.items())
        )
    executed = [r for r in rows if r["executed"]]
    if executed:
        ok = sum(r["success"] for r in executed)
        timing = ", ".join(sorted({r.get("go_on", "toppra") for r in executed}))
        lines.append(
            f"executed with {timing}: {ok} of {len(executed)} assembled; robot seconds executed "
            + ", ".join(f"seed {r['seed']} {r['robot_executed'].get('total', 0):.1f}" for r in executed)
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", type=Path, default=ROOT / "configs" / "demo.yaml")
    ap.add_argument("--seeds", type=int, default=20, help="number of seeds (default 20)")
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--execute", type=int, default=0, help="execute the first K seeds too (toppra timing)")
    ap.add_argument(
        "--go-on",
        choices=TIMINGS,
        default="toppra",
        help="the timing of the plan the pipeline goes on with (executes, re-checks)",
    )
    ap.add_argument("--out", type=Path, default=None, help="folder for cycle_time.jsonl and the run folders")
    args = ap.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="cycle_time_"))
    out.mkdir(parents=True, exist_ok=True)
    log = out / "cycle_time.jsonl"
    done = {}
    if log.exists():  # resumable: seeds already in the log are not run again
        for line in log.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                done[r["seed"]] = r
    rows = []
    for k, seed in enumerate(range(args.first_seed, args.first_seed + args.seeds)):
        execute = k < args.execute
        if seed in done and done[seed]["executed"] == execute and done[seed].get("go_on", "toppra") == args.go_on:
            rows.append(done[seed])
            continue
        t0 = time.perf_counter()
        try:
            row = run_seed(args.config, seed, out, execute, args.go_on)
        except UserError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        rows.append(row)
        with log.open("a") as f:
            f.write(json.dumps(row) + "\n")
        new = row.get("toppra_robot", {}).get("total")
        old = row.get("trapezoid_robot", {}).get("total")
        print(
            f"seed {seed}: {time.perf_counter() - t0:.0f} s wall; robot s {old} -> {new}; "
            f"{'success' if row['success'] else row['failed_stage']}",
            flush=True,
        )
    print(report(rows))
    print(f"rows: {log}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
