"""Collision-checking throughput of the Nextage: arm configurations per second on one core.

World: the table and two parts (a 50 mm cube and a 60 x 60 mm cylinder, as
meshes) in front of the robot. Configurations are uniform within the joint
limits. The rate is measured in process CPU time (one core; BLAS threads are
pinned to 1) and in wall time. Target: >= 20,000 configurations per second.

Run: .venv/bin/python benchmarks/robots_collision.py [--n 20000] [--batch 2000]
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import time

import numpy as np
import trimesh

from asmteach.core.interfaces import Obstacle
from asmteach.plugins.robots.nextage.robot import NextagePyBullet


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=20000)
    ap.add_argument("--batch", type=int, default=2000, help="configurations per call")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    robot = NextagePyBullet({}, seed=args.seed)
    T_a, T_b = np.eye(4), np.eye(4)
    T_a[:3, 3] = [0.40, 0.15, 0.025]
    T_b[:3, 3] = [0.45, -0.15, 0.03]
    robot.set_obstacles(
        [
            Obstacle("cube", trimesh.creation.box((0.05, 0.05, 0.05)), T_a),
            Obstacle("cylinder", trimesh.creation.cylinder(0.03, 0.06, sections=32), T_b),
        ]
    )
    rng = np.random.default_rng(args.seed)
    for arm in robot.arms:
        lo, hi = robot.joint_limits(arm)
        qs = rng.uniform(lo, hi, size=(args.n, len(lo)))
        robot.in_collision(arm, qs[:10])  # warm-up: builds the pair tables
        c0, w0 = time.process_time(), time.perf_counter()
        hits = np.concatenate([robot.in_collision(arm, qs[i : i + args.batch]) for i in range(0, args.n, args.batch)])
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        m = 500
        c1 = time.process_time()
        robot.clearance(arm, qs[:m])
        ccpu = time.process_time() - c1
        print(
            f"{arm} arm: {args.n} configurations, {100 * hits.mean():.1f} % in collision; "
            f"{args.n / cpu:,.0f} configs/s (CPU time, one core), {args.n / wall:,.0f} configs/s (wall); "
            f"clearance {m / ccpu:,.0f} configs/s"
        )
    robot.close()


if __name__ == "__main__":
    main()
