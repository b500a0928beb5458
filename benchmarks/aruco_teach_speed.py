"""Benchmark: teaching from 30 rendered 1280x720 frames (target <= 2 s on 2 cores).

Run: .venv/bin/python benchmarks/aruco_teach_speed.py [--structure configs/parts/set1/t_slot.yaml ...]
     [--orientation 0] [--repeats 5] [--out docs/results/teaching_speed.md]
Default: all ten structures of configs/parts/set1 and set2. Prints, per structure,
the median and maximum wall time of ArucoTeacher.teach (detection, PnP,
fusion, joint adjustment, v_a and its python-fcl check) over the repeats,
the frames used and the source of v_a, and the 1-minute load average of the
machine (shared machines make wall times noisy).
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
import time
from pathlib import Path

import numpy as np

from asmteach.core.io import write_text
from asmteach.core.parts import build_part, load_structure
from asmteach.plugins.detectors.aruco.camera import c615_like
from asmteach.plugins.detectors.aruco.scene import DemoSettings, render_demo_frames
from asmteach.plugins.detectors.aruco.teacher import ArucoTeacher

ROOT = Path(__file__).resolve().parents[1]
ALL = sorted((ROOT / "configs/parts/set1").glob("*.yaml")) + sorted((ROOT / "configs/parts/set2").glob("*.yaml"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--structure", action="append", help="structure YAML (repeatable); default: all ten")
    ap.add_argument("--frames", type=int, default=30, help="total frames (approach + assembled)")
    ap.add_argument("--orientation", type=int, default=0, help="demonstration orientation 0-4")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", type=Path, help="also write the table as markdown here")
    args = ap.parse_args()
    cam = c615_like()
    approach = args.frames // 3
    settings = DemoSettings(frames=args.frames - approach, approach_frames=approach, orientation=args.orientation)
    rows = []
    for path in args.structure or ALL:
        task = load_structure(path)
        a, b = build_part(task.part_a), build_part(task.part_b)
        frames = [img for _, img, _ in render_demo_frames(a, b, task, cam, settings, seed=0)]
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            learned = ArucoTeacher().teach(frames, cam, task)
            times.append(time.perf_counter() - t0)
        ev = learned.evidence
        load = os.getloadavg()[0]
        row = (
            f"| {task.name} | {np.median(times):.3f} | {max(times):.3f} | {len(ev.frames_used) if ev else '?'} "
            f"| {ev.insertion_source if ev else '?'} | {load:.2f} |"
        )
        print(row, flush=True)
        rows.append((row, float(np.median(times))))
    worst = max(t for _, t in rows)
    head = (
        f"# Teaching speed: {args.frames} frames {cam.width}x{cam.height}, orientation {args.orientation}, "
        f"{args.repeats} repeats, {os.cpu_count()} cores\n\n"
        f"Command: `.venv/bin/python {shlex.join(sys.argv)}`\n\n"
        "| structure | median s | max s | frames used | v_a source | load avg (1 min) |\n"
        "|---|---|---|---|---|---|\n"
    )
    text = head + "\n".join(r for r, _ in rows) + f"\n\nWorst median {worst:.3f} s (target <= 2 s).\n"
    print(f"worst median {worst:.3f} s (target <= 2 s)")
    if args.out:
        write_text(args.out, text)


if __name__ == "__main__":
    main()
