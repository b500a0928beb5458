"""IK benchmark of the Nextage arms: success, precision and time on reachable targets.

Targets are the TCP poses (FK) of random configurations within the joint
limits that are free of collision (self and table), so every target is
reachable. IK starts from the home configuration (the robot's default seed).
Targets: >= 99 % success, position error <= 0.1 mm, orientation <= 0.1 deg,
median <= 2 ms per solve.

Run: .venv/bin/python benchmarks/robots_ik.py [--n 1000] [--chest]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from asmteach.core import geometry
from asmteach.plugins.robots.nextage.robot import NextagePyBullet


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=1000, help="targets per arm")
    ap.add_argument("--chest", action="store_true", help="7-DOF arms (chest joint included)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    robot = NextagePyBullet({"use_chest": args.chest}, seed=args.seed)
    rng = np.random.default_rng(args.seed)
    for arm in robot.arms:
        lo, hi = robot.joint_limits(arm)
        qs = rng.uniform(lo, hi, size=(args.n * 4, len(lo)))
        qs = qs[~robot.in_collision(arm, qs)][: args.n]
        times, pos, rot, ok = [], [], [], 0
        for q in qs:
            T = robot.fk(arm, q)
            t0 = time.perf_counter()
            res = robot.kin.ik(arm, T, robot.home(arm), rng=rng, flipped=False)
            times.append(time.perf_counter() - t0)
            if res.success:
                ok += 1
                T2 = robot.fk(arm, res.q)
                pos.append(np.linalg.norm(T2[:3, 3] - T[:3, 3]))
                rot.append(geometry.rotation_distance(T2, T))
        t = np.asarray(times) * 1000.0
        print(
            f"{arm} arm ({len(lo)} DOF), {len(qs)} reachable targets: success {100.0 * ok / len(qs):.2f} %, "
            f"position error max {1000 * max(pos):.4f} mm, orientation error max {math.degrees(max(rot)):.4f} deg, "
            f"time median {np.median(t):.2f} ms, mean {np.mean(t):.2f} ms, p95 {np.percentile(t, 95):.2f} ms"
        )
    robot.close()


if __name__ == "__main__":
    main()
