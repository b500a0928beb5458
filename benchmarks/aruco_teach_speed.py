"""Benchmark: teaching from 30 rendered 1280x720 frames (target <= 2 s on 2 cores).

Run: .venv/bin/python benchmarks/aruco_teach_speed.py [--structure configs/parts/set1/peg_in_hole.yaml]
Prints the wall time of ArucoTeacher.teach (detection, PnP, fusion, joint
adjustment, v_a and its python-fcl check) over several repeats.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from asmteach.core.parts import build_part, load_structure
from asmteach.plugins.detectors.aruco.camera import c615_like
from asmteach.plugins.detectors.aruco.scene import DemoSettings, render_demo_frames
from asmteach.plugins.detectors.aruco.teacher import ArucoTeacher

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--structure", default=str(ROOT / "configs/parts/set1/peg_in_hole.yaml"))
    ap.add_argument("--frames", type=int, default=30, help="total frames (approach + assembled)")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    task = load_structure(args.structure)
    a, b = build_part(task.part_a), build_part(task.part_b)
    cam = c615_like()
    approach = args.frames // 3
    settings = DemoSettings(frames=args.frames - approach, approach_frames=approach)
    frames = [img for _, img, _ in render_demo_frames(a, b, task, cam, settings, seed=0)]
    times = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        learned = ArucoTeacher().teach(frames, cam, task)
        times.append(time.perf_counter() - t0)
    ev = learned.evidence
    print(f"{task.name}: {len(frames)} frames {cam.width}x{cam.height}; teach wall time "
          f"median {np.median(times):.3f} s, min {min(times):.3f} s over {args.repeats} runs")
    print(f"  frames used {len(ev.frames_used) if ev else '?'}; v_a source {ev.insertion_source if ev else '?'}")


if __name__ == "__main__":
    main()
