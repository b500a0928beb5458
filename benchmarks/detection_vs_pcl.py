"""Detection time per step, ``cvfh_icp`` against the PCL reference (``shared/tools/pcl-ref``), on the same scenes.

Scenes of corpus parts the detector was not tuned on (:func:`asmteach.core.corpus.part_corpus`, seeded scenes of
:mod:`asmteach.plugins.detectors.cvfh.corpus_measure`: a stable rest drawn by probability, a random yaw and place,
the scene Kinect with noise) are written in the reference's input format (``make_inputs.py``: the model cloud,
20 000 surface samples in the part frame; the 42 noise-free views of the part; each scene as a binary PCD in the
camera frame, OpenCV axes) and both detectors run on them **interleaved per scene** (the order alternates), so the
load other processes put on the machine falls on both alike; the load average is recorded per scene. Build the
reference first (outside ``shared/``, never in CI)::

    cmake -S shared/tools/pcl-ref -B /work/pclref-build -DCMAKE_BUILD_TYPE=Release && cmake --build /work/pclref-build
    .venv/bin/python benchmarks/detection_vs_pcl.py --pcl-ref /work/pclref-build/pcl_ref --parts 8 --scenes 3

Without ``--pcl-ref`` (or when the binary is missing) it says so and exits 0.

Steps compared (milliseconds; the reference's ``timing_ms`` keys, ours ``Detection.timing_ms``):

==============  ================================  ============================================
step            reference                         ours
==============  ================================  ============================================
segmentation    voxel + plane + cluster           segment (checks, table RANSAC) + cluster
normals         normals                           normals (voxel grid of the cluster, normals)
descriptors     cvfh_crh                          descriptors (CVFH regions, CRH)
matching        match + crh_align                 matching (views, CRH rolls, hypotheses, pre-score)
ICP             icp (+ outlier count)             icp (coarse + fine, twins and nudges included)
verification    (none: best fitness wins)         verify
total           detect_total (file loading out)   total (view database prepared beforehand)
==============  ================================  ============================================

Success for both: the rough pose within 5 mm / 5 deg of the truth, symmetry-aware
(:func:`asmteach.core.pose_error.pose_error` with the part's symmetries). The reference always reports its
best-fitness pose; ours reports ``found: false`` rather than a pose it cannot verify, so its *wrong* count is
what precision means.
Rows (one per scene, both detectors) go to ``benchmarks/out/detection_vs_pcl.csv``; the per-step medians and
ratios are printed, with the CPU times (ours: the detection's process time, ``timing_ms["cpu"]``; the
reference: its whole process, file loading included) and our Open3D ICP passes per scene
(``details["icp_passes"]``). On a machine loaded by other jobs the wall clock mostly counts their turns, so
the detection CPU times are compared too: ours measured, the reference's estimated as its ``detect_total``
times its process's CPU / wall (its share of a core; columns ``*_detect_cpu_ms``).
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import ModuleType

import numpy as np

OUT = Path(__file__).resolve().parent / "out" / "detection_vs_pcl.csv"
MAKE_INPUTS = Path(__file__).resolve().parents[2] / "shared" / "tools" / "pcl-ref" / "make_inputs.py"

STEPS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    # step: (reference keys, our keys)
    "segmentation": (("voxel", "plane", "cluster"), ("segment", "cluster")),
    "normals": (("normals",), ("normals",)),
    "descriptors": (("cvfh_crh",), ("descriptors",)),
    "matching": (("match", "crh_align"), ("matching",)),
    "icp": (("icp",), ("icp",)),
    "verification": ((), ("verify",)),
    "total": (("detect_total",), ("total",)),
}
"""Each compared step and the ``timing_ms`` keys summed into it."""


def load_make_inputs(path: Path) -> ModuleType:
    """The reference's ``make_inputs.py`` as a module (its writers and renderer), leaving no ``__pycache__``."""
    spec = importlib.util.spec_from_file_location("pclref_make_inputs", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    before, sys.dont_write_bytecode = sys.dont_write_bytecode, True  # shared/ stays unmodified
    try:
        spec.loader.exec_module(module)
    finally:
        sys.dont_write_bytecode = before
    return module


def step_ms(timing: dict[str, float], keys: tuple[str, ...]) -> float:
    """Sum of the ``timing`` entries ``keys`` (ms); absent keys count 0."""
    return float(sum(timing.get(k, 0.0) for k in keys))


def run_ref(binary: str, db: Path, scene: Path, model: Path) -> dict:
    """``pcl_ref detect`` on one scene: its JSON (``ok`` false and empty timing when it fails).

    ``cpu_ms`` is the CPU time of the whole process (user + system, file loading included: an upper bound on its
    detection's), ``wall_ms`` its wall-clock time.
    """
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run(
        [binary, "detect", "--db", str(db), "--scene", str(scene), "--model", str(model)],
        capture_output=True,
        text=True,
        check=False,
    )
    wall_ms = 1000.0 * (time.perf_counter() - t0)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_ms = 1000.0 * (after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
    if p.returncode not in (0, 2):
        return {"ok": False, "timing_ms": {}, "cpu_ms": cpu_ms, "wall_ms": wall_ms, "error": p.stderr.strip()[-200:]}
    return {**json.loads(p.stdout), "cpu_ms": cpu_ms, "wall_ms": wall_ms}


def detect_cpu_estimate(detect_ms: float, cpu_ms: float, wall_ms: float) -> float:
    """The reference's detection CPU time (ms): its detection's wall time times the share of a core its process got.

    On a loaded machine the wall clock counts the other jobs' turns; a single-threaded process's CPU / wall is its
    share of a core, assumed the same while it loads its files and while it detects.
    """
    return detect_ms * min(1.0, cpu_ms / wall_ms) if wall_ms > 0 else detect_ms


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pcl-ref", default=None, help="the built pcl_ref executable")
    ap.add_argument("--parts", type=int, default=8, help="evenly spread corpus parts (0: all)")
    ap.add_argument("--only", nargs="*", default=None, help="part names to run instead")
    ap.add_argument("--scenes", type=int, default=3, help="scenes per part")
    ap.add_argument("--seed", type=int, default=0, help="corpus and scene seed")
    ap.add_argument("--out", type=Path, default=OUT, help="CSV, one row per scene")
    ap.add_argument("--work", type=Path, default=None, help="folder for the reference's inputs (default: temporary)")
    args = ap.parse_args()
    if not args.pcl_ref or not os.access(args.pcl_ref, os.X_OK):
        print(
            f"PCL reference not available ({args.pcl_ref!r}): build shared/tools/pcl-ref (see its README) and "
            "pass --pcl-ref PATH; nothing measured"
        )
        return

    from asmteach.core import registry
    from asmteach.core.config import TableSettings
    from asmteach.core.corpus import part_corpus
    from asmteach.core.parts import PartSpec, build_part
    from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings
    from asmteach.core.pose_error import pose_error
    from asmteach.core.symmetry import equivalent_transforms
    from asmteach.plugins.detectors.cvfh.corpus_measure import rest_poses, scene_pose
    from asmteach.plugins.detectors.cvfh.scenes import default_camera_pose, render_table_scene

    mi = load_make_inputs(MAKE_INPUTS)
    corpus = part_corpus(seed=args.seed)
    if args.only:
        corpus = [c for c in corpus if c.name in set(args.only)]
    elif args.parts and args.parts < len(corpus):
        corpus = [corpus[int(i)] for i in np.linspace(0, len(corpus) - 1, args.parts).round()]
    table = TableSettings()
    T_cam = default_camera_pose(table)
    T_cam_world = np.linalg.inv(T_cam)
    rows: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        for cp in corpus:
            folder = work / cp.name
            (folder / "model").mkdir(parents=True, exist_ok=True)
            (folder / "scenes").mkdir(exist_ok=True)
            # The reference's inputs, in the corpus mesh's own frame (the frame our poses are given in).
            stl = folder / "model" / "model.stl"
            cp.mesh.export(stl)
            samples, _ = __import__("trimesh").sample.sample_surface(cp.mesh, 20000, seed=args.seed)
            model_pcd = folder / "model" / "model_cloud.pcd"
            mi.write_pcd(str(model_pcd), samples)
            mi.make_views(cp.mesh, str(folder / "views"), 0.9)
            db = folder / "db.txt"
            subprocess.run(
                [args.pcl_ref, "train", "--views", str(folder / "views" / "views.txt"), "--out", str(db)],
                capture_output=True,
                text=True,
                check=True,
            )
            part = build_part(PartSpec(name=cp.name, mesh=str(stl), mesh_units="m"))
            detector = registry.create("detectors", "cvfh_icp", {}, seed=args.seed)
            detector.prepare(part)  # view database and model built (or loaded) before the clock, as for the reference
            com = np.asarray(cp.mesh.center_mass, float)
            rests, probs = rest_poses(cp.mesh, com)
            syms = equivalent_transforms(cp.mesh, com)
            for i in range(args.scenes):
                rng = np.random.default_rng([args.seed, i, 22])  # the scenes of corpus_measure.run_part
                k, _, T_true = scene_pose(cp.mesh, rests, probs, rng, table)
                scene = render_table_scene(
                    DepthCamera(KinectSettings(), seed=1000 * args.seed + i),
                    cp.mesh,
                    T_true,
                    table=table,
                    T_world_cam=T_cam,
                )
                pcd = folder / "scenes" / f"scene_{i:03d}.pcd"
                mi.write_pcd(str(pcd), scene.cloud @ T_cam_world[:3, :3].T + T_cam_world[:3, 3])
                load = os.getloadavg()[0]
                got: dict[str, dict] = {}
                for who in ("ours", "ref") if i % 2 == 0 else ("ref", "ours"):
                    if who == "ours":
                        det = detector.detect(scene.cloud, part, viewpoint=T_cam[:3, 3])
                        got["ours"] = {
                            "timing": det.timing_ms,
                            "pose": det.rough if det.found else None,
                            "found": det.found,
                            "cpu_ms": det.timing_ms.get("cpu", 0.0),
                            "icp_passes": det.details.get("icp_passes"),
                            "detect_cpu_ms": det.timing_ms.get("cpu", 0.0),
                        }
                    else:
                        r = run_ref(args.pcl_ref, db, pcd, model_pcd)
                        pose = T_cam @ np.asarray(r["pose"], float) if r.get("ok") else None
                        est = detect_cpu_estimate(
                            float(r.get("timing_ms", {}).get("detect_total", 0.0)), r["cpu_ms"], r["wall_ms"]
                        )
                        got["ref"] = {
                            "timing": r.get("timing_ms", {}),
                            "pose": pose,
                            "found": bool(r.get("ok")),
                            "cpu_ms": r["cpu_ms"],
                            "icp_passes": None,
                            "detect_cpu_ms": est,
                        }
                row: dict = {
                    "part": cp.name,
                    "family": cp.family,
                    "scene": i,
                    "rest": k,
                    "part_points": int((scene.frame.labels == 1).sum()),
                    "load1": round(load, 2),
                }
                for who, g in got.items():
                    mm = deg = None
                    if g["pose"] is not None:
                        err = pose_error(np.asarray(g["pose"], float), T_true, right=syms)
                        mm, deg = err.position_mm, err.angle_deg
                    ok = mm is not None and mm <= 5.0 and deg <= 5.0
                    row.update(
                        {
                            f"{who}_found": g["found"],
                            f"{who}_success": ok,
                            f"{who}_wrong": g["found"] and not ok,
                            f"{who}_pos_mm": None if mm is None else round(mm, 2),
                            f"{who}_rot_deg": None if deg is None else round(deg, 2),
                            f"{who}_cpu_ms": round(g["cpu_ms"], 1),
                            f"{who}_icp_passes": g["icp_passes"],
                            f"{who}_detect_cpu_ms": round(g["detect_cpu_ms"], 1),
                        }
                    )
                    for step, (ref_keys, our_keys) in STEPS.items():
                        keys = our_keys if who == "ours" else ref_keys
                        row[f"{who}_{step}_ms"] = round(step_ms(g["timing"], keys), 2)
                rows.append(row)
                print(
                    f"{cp.name:24s} {i}  load {load:4.1f}  ours {row['ours_total_ms']:7.1f} ms "
                    f"({'ok' if row['ours_success'] else 'WRONG' if row['ours_wrong'] else 'miss'})  "
                    f"ref {row['ref_total_ms']:7.1f} ms "
                    f"({'ok' if row['ref_success'] else 'WRONG' if row['ref_wrong'] else 'miss'})",
                    flush=True,
                )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with args.out.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    n = len(rows)
    load = float(np.median([r["load1"] for r in rows]))
    print(
        f"\n{len(corpus)} parts, {n} scenes; load average (1 min) median {load:.1f}, "
        f"now {', '.join(f'{x:.1f}' for x in os.getloadavg())}"
    )
    print(f"{'step':14s} {'ours ms':>9s} {'PCL ms':>9s} {'ratio':>7s}   (medians over scenes; ratio = ours / PCL)")
    for step in STEPS:
        a = float(np.median([r[f"ours_{step}_ms"] for r in rows]))
        b = float(np.median([r[f"ref_{step}_ms"] for r in rows]))
        ratio = f"{a / b:7.2f}" if b > 0 else "    n/a"
        print(f"{step:14s} {a:9.1f} {b:9.1f} {ratio}")
    paired = float(np.median([r["ours_total_ms"] / r["ref_total_ms"] for r in rows if r["ref_total_ms"] > 0]))
    print(f"median of the per-scene total ratios: {paired:.2f}")
    a, b = (float(np.median([r[f"{who}_cpu_ms"] for r in rows])) for who in ("ours", "ref"))
    print(f"CPU time, median: ours {a:.1f} ms (detect), PCL {b:.1f} ms (whole process, file loading included)")
    a, b = (float(np.median([r[f"{who}_detect_cpu_ms"] for r in rows])) for who in ("ours", "ref"))
    paired = float(
        np.median([r["ours_detect_cpu_ms"] / r["ref_detect_cpu_ms"] for r in rows if r["ref_detect_cpu_ms"] > 0])
    )
    print(
        f"detection CPU time, median: ours {a:.1f} ms, PCL {b:.1f} ms (estimated: its detect_total times its "
        f"process's CPU / wall); ratio {a / b:.2f}, median of the per-scene ratios {paired:.2f}"
    )
    print(
        f"ICP passes per scene (ours): median {np.median([r['ours_icp_passes'] for r in rows]):.0f}, "
        f"mean {np.mean([r['ours_icp_passes'] for r in rows]):.1f}"
    )
    for who in ("ours", "ref"):
        print(
            f"{who:4s}: success {sum(r[f'{who}_success'] for r in rows)}/{n}, "
            f"found {sum(r[f'{who}_found'] for r in rows)}, "
            f"wrong poses reported {sum(r[f'{who}_wrong'] for r in rows)}"
        )
    print(f"rows -> {args.out}")


if __name__ == "__main__":
    main()
