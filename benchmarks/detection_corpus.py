"""Detection on parts the detector was not tuned on: 5 seeded scenes per part of the part corpus.

Each part of :func:`asmteach.core.corpus.part_corpus` is written as an STL and loaded back through
:func:`~asmteach.core.parts.build_part` (``--cad``: as a CAD user sends it, millimetres with a few faces
missing, :func:`~asmteach.core.corpus.write_cad_stl`); each scene puts the corpus mesh in one of its stable rests
(trimesh, drawn by probability) at a random yaw and position on the table, renders it with the scene
Kinect (noise on) and runs the detector with the camera's centre as the viewpoint. Errors are
symmetry-aware (the part's own symmetries, :func:`asmteach.core.symmetry.part_symmetries`, and a
continuous turn about an axis of revolution, found here by sampling): position of the part origin in mm,
geodesic rotation in degrees, of the rough pose (the detector alone, no corrector)::

    .venv/bin/python benchmarks/detection_corpus.py                 # whole corpus, 5 scenes each
    .venv/bin/python benchmarks/detection_corpus.py --parts 10      # every 4th-ish part (evenly spread)

Prints one line per scene (found and its error, or the rejection reason) and the totals against the
targets: success (found within 5 mm / 5 deg) on >= 95 % of scenes, and no pose more than 5 mm / 5 deg
off reported as found. Rows go to ``benchmarks/out/detection_corpus.csv``.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import re
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh

from asmteach.core import geometry, registry
from asmteach.core.config import TableSettings
from asmteach.core.interfaces import Detector, PartModel
from asmteach.core.parts import PartSpec, build_part
from asmteach.core.symmetry import part_symmetries
from asmteach.plugins.detectors.cvfh.scenes import default_camera_pose, place_on_table, render_table_scene
from asmteach.plugins.detectors.depth_camera import DepthCamera, KinectSettings

OUT = Path(__file__).resolve().parent / "out" / "detection_corpus.csv"
AREA = (0.24, 0.34)
"""Work-area extent (x, y, metres) the part's centre is drawn from, around the work centre (0.45, 0)."""


def rest_poses(mesh: trimesh.Trimesh, com: np.ndarray, min_share: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """``(T_table_part (k, 4, 4), probability (k,))`` of trimesh's stable rests, those below ``min_share`` of the
    likeliest dropped (a tube's side is 64 facets of 1.5 % each: the threshold is relative)."""
    T, p = trimesh.poses.compute_stable_poses(mesh, center_mass=np.asarray(com, float))
    T, p = np.asarray(T, float), np.asarray(p, float)
    keep = p >= min_share * p.max()
    return T[keep], p[keep] / p[keep].sum()


def symmetry_set(mesh: trimesh.Trimesh, com: np.ndarray, tol: float = 0.0005) -> np.ndarray:
    """Part-frame transforms ``(m, 4, 4)`` that map the part onto itself (about the centre of mass).

    :func:`part_symmetries`, whose surfaces of revolution get turns in 10 deg steps only (an error could
    keep 5 deg of a turn that changes nothing), times every 1 deg turn about the axis of revolution when
    the part has one (a principal axis about which turns of 7 and 31 deg map it onto itself).
    """
    from asmteach.core.symmetry import SymmetryFinder, axis_rotations, principal_frame

    group = np.asarray(part_symmetries(mesh, com, tol))
    finder = SymmetryFinder(mesh, np.asarray(mesh.convex_hull.vertices), com, tol=tol, corners=False)
    for axis in principal_frame(mesh).T:
        if all(finder.maps(R) for R in axis_rotations(axis, np.radians([7.0, 31.0]))):
            turns = [geometry.from_rotation(R, com - R @ com) for R in axis_rotations(axis, np.radians(np.arange(360)))]
            return np.einsum("aij,bjk->abik", group, np.asarray(turns)).reshape(-1, 4, 4)
    return group


def symmetric_error(T_est: np.ndarray, T_true: np.ndarray, syms: np.ndarray) -> tuple[float, float]:
    """``(mm, deg)`` of ``T_est`` against the nearest ``T_true @ S`` (the same solid in the same place)."""
    eq = np.einsum("ij,sjk->sik", T_true, syms)
    pos = 1000.0 * np.linalg.norm(eq[:, :3, 3] - T_est[:3, 3], axis=1)
    cos = (np.einsum("ij,sij->s", T_est[:3, :3], eq[:, :3, :3]) - 1.0) / 2.0
    rot = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    i = int(np.argmin(pos + rot))
    return float(pos[i]), float(rot[i])


def scene_pose(mesh: trimesh.Trimesh, rests: np.ndarray, probs: np.ndarray, rng: np.random.Generator,
               table: TableSettings) -> tuple[int, float, np.ndarray]:
    """``(rest index, yaw rad, T_world_part)`` of one scene: a rest drawn by probability, yaw and xy uniform."""
    k = int(rng.choice(len(rests), p=probs))
    yaw = float(rng.uniform(-np.pi, np.pi))
    xy = np.array([0.45, 0.0]) + rng.uniform(-0.5 * np.asarray(AREA), 0.5 * np.asarray(AREA))
    return k, yaw, place_on_table(mesh, rests[k], yaw, xy, table.height)


def load_part(name: str, mesh: trimesh.Trimesh, folder: Path, seed: int, cad: bool) -> PartModel:
    """The part as asmteach loads it: from a closed metre STL, or (``cad``) as a CAD user sends it (mm STL
    with open faces, :func:`~asmteach.core.corpus.write_cad_stl`)."""
    from asmteach.core.corpus import write_cad_stl

    path = folder / f"{name}.stl"
    if cad:
        write_cad_stl(mesh, path, seed=seed)
    else:
        mesh.export(path)
    return build_part(PartSpec(name=name, mesh=str(path), mesh_units="mm" if cad else "m"))


def run_part(name: str, mesh: trimesh.Trimesh, part: PartModel, detector: Detector, scenes: int, seed: int,
             tol_mm: float = 5.0, tol_deg: float = 5.0) -> list[dict]:
    """Render ``scenes`` scenes of ``mesh`` (the truth) and detect ``part`` (as loaded) in each."""
    table = TableSettings()
    com = np.asarray(mesh.center_mass, float)
    rests, probs = rest_poses(mesh, com)
    syms = symmetry_set(mesh, com)
    T_cam = default_camera_pose(table)
    t0 = time.perf_counter()
    detector.prepare(part)
    prep_s = time.perf_counter() - t0
    rows = []
    for i in range(scenes):
        rng = np.random.default_rng([seed, i, 22])
        k, yaw, T_true = scene_pose(mesh, rests, probs, rng, table)
        scene = render_table_scene(DepthCamera(KinectSettings(), seed=1000 * seed + i), mesh, T_true,
                                   table=table, T_world_cam=T_cam)
        det = detector.detect(scene.cloud, part, viewpoint=T_cam[:3, 3])
        row = {"part": name, "scene": i, "rest": k, "yaw_deg": round(math.degrees(yaw), 1),
               "part_points": int((scene.frame.labels == 1).sum()), "found": det.found,
               "pos_mm": None, "rot_deg": None, "success": False, "wrong_found": False,
               "reason": det.reason or "", "source": det.details.get("source", ""),
               "detect_ms": det.timing_ms.get("total"), "prepare_s": round(prep_s, 1) if i == 0 else 0.0,
               "symmetries": len(syms)}
        alts = [np.asarray(a["T_world_part"]) for a in det.details.get("ambiguous", [])]
        row["alternatives"] = len(alts)  # hull twins the view cannot tell apart, listed with the found pose
        row["truth_in_alternatives"] = any(
            np.all(np.array(symmetric_error(T, T_true, syms)) <= (tol_mm, tol_deg)) for T in alts)
        if det.found and det.rough is not None:
            mm, deg = symmetric_error(det.rough, T_true, syms)
            ok = mm <= tol_mm and deg <= tol_deg
            row.update(pos_mm=round(mm, 2), rot_deg=round(deg, 2), success=ok, wrong_found=not ok)
        rows.append(row)
    return rows


def describe(row: dict) -> str:
    if row["found"]:
        tag = "ok   " if row["success"] else "WRONG"
        flag = ""
        if row["alternatives"]:
            truth = " incl. the truth" if row["truth_in_alternatives"] else ""
            flag = f", {row['alternatives']} twin(s) listed{truth}"
        return f"{tag} {row['pos_mm']:6.2f} mm {row['rot_deg']:6.2f} deg ({row['source']}{flag})"
    return f"miss  {row['reason']}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", type=int, default=0, help="evenly spread subsample of this many parts (0: all)")
    ap.add_argument("--only", nargs="*", default=None, help="part names to run (default: all)")
    ap.add_argument("--scenes", type=int, default=5, help="scenes per part")
    ap.add_argument("--seed", type=int, default=0, help="corpus and scene seed")
    ap.add_argument("--detector", default="cvfh_icp", help="detector plugin")
    ap.add_argument("--out", type=Path, default=OUT, help="CSV of every scene")
    ap.add_argument("--cad", action="store_true", help="load each part from a CAD-style mm STL with open faces")
    args = ap.parse_args()

    from asmteach.core.corpus import part_corpus

    corpus = part_corpus(seed=args.seed)
    if args.only:
        corpus = [c for c in corpus if c.name in set(args.only)]
    elif args.parts and args.parts < len(corpus):
        corpus = [corpus[int(i)] for i in np.linspace(0, len(corpus) - 1, args.parts).round()]
    rows: list[dict] = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for cp in corpus:
            part = load_part(cp.name, cp.mesh, Path(tmp), args.seed, args.cad)
            detector = registry.create("detectors", args.detector, {}, seed=args.seed)
            assert isinstance(detector, Detector)
            got = run_part(cp.name, cp.mesh, part, detector, args.scenes, args.seed)
            for r in got:
                r["family"] = cp.family
                print(f"{cp.name:24s} {r['scene']}  {describe(r)}", flush=True)
            rows += got
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with args.out.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    n = len(rows)
    found = sum(r["found"] for r in rows)
    ok = sum(r["success"] for r in rows)
    wrong = [r for r in rows if r["wrong_found"]]
    print(f"\n{len(corpus)} parts, {n} scenes, {time.perf_counter() - t0:.0f} s, load {os.getloadavg()[0]:.1f}")
    print(f"found {found}/{n}; success (<= 5 mm, 5 deg) {ok}/{n} = {100.0 * ok / max(n, 1):.1f} % (target >= 95 %)")
    flagged = [r for r in wrong if r["truth_in_alternatives"]]
    print(f"wrong poses reported as found: {len(wrong)} (target 0), of which {len(flagged)} flagged ambiguous with "
          "the right pose among details['ambiguous']")
    for r in wrong:
        note = " (flagged, truth listed)" if r["truth_in_alternatives"] else ""
        print(f"  {r['part']} scene {r['scene']}: {r['pos_mm']} mm, {r['rot_deg']} deg{note}")
    misses = {}
    for r in rows:
        if not r["found"]:
            why = r["reason"].split("rejected (", 1)[-1]  # the closest miss's reason, else the whole reason
            key = "ambiguous" if why.startswith("ambiguous") else re.sub(r"\d+(\.\d+)?", "N", why.split(":")[0])[:60]
            misses[key] = misses.get(key, 0) + 1
    print("not found, by reason:", dict(sorted(misses.items(), key=lambda kv: -kv[1])))
    print(f"rows -> {args.out}")


if __name__ == "__main__":
    main()
