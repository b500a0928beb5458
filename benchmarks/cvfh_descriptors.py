"""Time the CVFH + CRH descriptors on one rendered view of about 3000 points.

Renders a 60 x 40 x 30 mm L-block (two overlapping boxes) with Open3D ray casting through a pinhole camera
(fx = fy = 525, like the Kinect model), keeps every visible hit, and times, per view:

- ``normals``: :func:`estimate_normals_curvature` (10 mm radius, the input normals and curvatures of CVFH);
- ``cvfh``: :func:`compute_cvfh` (smooth regions, internal normals, one VFH per region);
- ``crh``: :func:`compute_crh` once per CVFH region;
- ``total`` (wall clock) and ``total_cpu`` (process CPU time, less sensitive to other load on a shared machine).

Usage::

    .venv/bin/python benchmarks/cvfh_descriptors.py [--points 3000] [--repeats 30] [--out DIR]

Prints the median and p90 of each stage in milliseconds and, with ``--out``, writes them to
``DIR/cvfh_descriptors.json``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
import trimesh

from asmteach.core.io import write_json  # importing asmteach.core loads libusb, which open3d needs
from asmteach.plugins.detectors.cvfh.descriptors import (
    CvfhParams,
    compute_crh,
    compute_cvfh,
    estimate_normals_curvature,
)

import open3d as o3d  # isort: skip  (after asmteach.core)


def l_block_view(n_target: int, distance: float = 0.7) -> np.ndarray:
    """Ray-cast an L-block seen obliquely from ``distance`` metres; return about ``n_target`` camera-frame points."""
    scene = o3d.t.geometry.RaycastingScene()
    for extents, centre in (((0.060, 0.040, 0.010), (0.0, 0.0, 0.005)), ((0.010, 0.040, 0.030), (0.025, 0.0, 0.015))):
        box = trimesh.creation.box(extents=extents)
        box.apply_translation(centre)
        mesh = o3d.t.geometry.TriangleMesh()
        mesh.vertex.positions = o3d.core.Tensor(np.asarray(box.vertices, dtype=np.float32))
        mesh.triangle.indices = o3d.core.Tensor(np.asarray(box.faces, dtype=np.int32))
        scene.add_triangles(mesh)
    # Camera looking at the block from above and to the side (world z up); OpenCV camera axes.
    eye = np.array([0.35, -0.45, 0.45])
    eye = eye / np.linalg.norm(eye) * distance
    target = np.array([0.0, 0.0, 0.01])
    z = (target - eye) / np.linalg.norm(target - eye)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    r_world_cam = np.column_stack([x, y, z])
    # Choose the image crop density so the part yields about n_target hits: step the pixel grid finely enough.
    hits = np.zeros((0, 3))
    for fx in (525.0, 1050.0, 2100.0, 4200.0):
        us, vs = np.meshgrid(np.arange(-160, 160), np.arange(-120, 120))
        dirs_cam = np.stack([us / fx, vs / fx, np.ones_like(us, dtype=float)], axis=-1).reshape(-1, 3)
        dirs = dirs_cam @ r_world_cam.T
        rays = np.hstack([np.broadcast_to(eye, dirs.shape), dirs]).astype(np.float32)
        t = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
        ok = np.isfinite(t)
        hits = dirs_cam[ok] * t[ok, None]  # camera frame (t is along the unnormalised ray, so z = t)
        if len(hits) >= n_target:
            break
    rng = np.random.default_rng(0)
    keep = rng.choice(len(hits), size=min(n_target, len(hits)), replace=False)
    return hits[np.sort(keep)]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=3000)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()

    points = l_block_view(args.points)
    params = CvfhParams()
    times: dict[str, list[float]] = {"normals": [], "cvfh": [], "crh": [], "cvfh+crh": [], "total": [], "total_cpu": []}
    n_regions = 0
    for _ in range(args.repeats + 1):  # the first round warms caches and is discarded
        c0 = time.process_time()
        t0 = time.perf_counter()
        normals, curv = estimate_normals_curvature(points, params.normal_radius)
        t1 = time.perf_counter()
        regions = compute_cvfh(points, normals, curv, params)
        t2 = time.perf_counter()
        for region in regions:
            compute_crh(points, normals, region.centroid)
        t3 = time.perf_counter()
        times["total_cpu"].append((time.process_time() - c0) * 1e3)
        n_regions = len(regions)
        for key, dt in (("normals", t1 - t0), ("cvfh", t2 - t1), ("crh", t3 - t2), ("cvfh+crh", t3 - t1)):
            times[key].append(dt * 1e3)
        times["total"].append((t3 - t0) * 1e3)
    summary = {
        key: {"median_ms": float(np.median(v[1:])), "p90_ms": float(np.percentile(v[1:], 90))}
        for key, v in times.items()
    }
    load = os.getloadavg()[0]
    print(f"view: {len(points)} points, {n_regions} CVFH regions, {args.repeats} repeats, load average {load:.1f}")
    for key, s in summary.items():
        print(f"  {key:9s} median {s['median_ms']:7.2f} ms   p90 {s['p90_ms']:7.2f} ms")
    if args.out is not None:
        write_json(
            args.out / "cvfh_descriptors.json",
            {"points": len(points), "regions": n_regions, "repeats": args.repeats, "load": load, "stages": summary},
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
