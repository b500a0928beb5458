"""Wall-clock detection time of cvfh_icp and fpfh_ransac on the same scenes, one process, one after the other.

The sweep (configs/experiments/detection_precision.yaml) runs trials in parallel next to whatever else the
machine does; this measures the detectors alone, on the random scenes of that experiment (seeds 32 on)::

    .venv/bin/python benchmarks/cvfh_timing.py --scenes 40

Prints the median wall-clock and CPU time of the detector (view database and placements prepared beforehand,
not counted) and the success rate, per detector, with the load average.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

from asmteach.core.io import read_yaml
from asmteach.plugins.detectors.cvfh.experiment import DetectionParams, DetectionPrecision

CONFIG = Path(__file__).resolve().parents[1] / "configs/experiments/detection_precision.yaml"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=40, help="random scenes per detector")
    ap.add_argument("--first-seed", type=int, default=32, help="first scene seed (32 = first random scene)")
    args = ap.parse_args()
    base = read_yaml(CONFIG)["params"]
    exp = DetectionPrecision(CONFIG.parent)
    out = {}
    for name in ("cvfh_icp", "fpfh_ransac"):
        params = DetectionParams.model_validate({**base, "detector": name})
        rows = [exp.run_trial(params, s, Path(".")) for s in range(args.first_seed, args.first_seed + args.scenes)]
        detect = [r.get("t_detect", r["t_total"]) for r in rows]
        out[name] = {
            "detect_ms_median": round(float(np.median(detect)), 1),
            "cpu_ms_median": round(float(np.median([r["t_cpu"] for r in rows])), 1),
            "success": round(float(np.mean([r["success"] for r in rows])), 3),
        }
    out["load_average"] = [round(x, 2) for x in os.getloadavg()]
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
