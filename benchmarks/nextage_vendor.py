"""Our Nextage model (``nextage.urdf``, primitive shapes) against the vendor's ``NextageOpen.urdf`` (COLLADA meshes).

Three comparisons, printed and written as CSV files under ``benchmarks/out/``:

1. ``nextage_vendor_fk.csv``: wrist (``*ARM_JOINT5_Link``) and TCP (``*ARM_TCP_Link``;
   on the vendor's model our gripper at its flange, see
   :mod:`asmteach.plugins.robots.nextage.vendor`) poses of both models at ``--n``
   seeded random configurations of all 15 joints, uniform within the limits both
   models share: max / median position difference (mm) and rotation angle (deg).
2. ``nextage_vendor_limits.csv``: each joint's lower / upper limit and velocity
   limit, ours and the vendor's, side by side.
3. ``nextage_vendor_links.csv``: per link, the collision geometry's volume (ours:
   the union of the primitives and its convex hull; the vendor's: the convex hull
   of its mesh, which is an open surface, so it has no volume of its own) and the
   surface distances between the two, both placed by each model's own FK at the
   first ``--configs`` of those configurations, in the world frame: the symmetric
   Hausdorff distance, the directed one from the vendor's surface to ours and back
   (between ``--samples`` seeded surface samples per geometry plus the mesh
   vertices: a few mm of sampling resolution), and how much of the vendor's surface
   lies more than 0.1 mm *outside* our primitives (the part a planner using our
   model would not see) with the largest distance outside (exact point-to-box /
   cylinder distance of those samples). The vendor's ``*ARM_JOINT5_Link`` is taken
   as the vendor option uses it, cut at the hand flange (its chuck hand is replaced
   by our gripper on both models).

Run from the project root (the vendor's files are read from ``../shared/data``)::

    .venv/bin/python benchmarks/nextage_vendor.py [--n 1000] [--configs 5] [--samples 20000] [--seed 0]
"""

from __future__ import annotations

import argparse
import csv
import sys
import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
import trimesh
from scipy.spatial import cKDTree

from asmteach.core.urdf import resolve_urdf
from asmteach.plugins.robots.nextage.build_urdf import URDF_PATH
from asmteach.plugins.robots.nextage.vendor import vendor_urdf

ROOT = Path(__file__).resolve().parents[1]
VENDOR = ROOT.parent / "shared" / "data" / "robots" / "nextage_open" / "urdf" / "NextageOpen.urdf"
OUT = ROOT / "benchmarks" / "out"
ARMS = ("LARM", "RARM")


def _models(path: Path) -> tuple[pin.Model, pin.GeometryModel]:
    model = pin.buildModelFromUrdf(str(path))
    geom = pin.buildGeomFromUrdf(model, str(path), pin.COLLISION, package_dirs=[str(path.parent)])
    return model, geom


def _configs(ours: pin.Model, vendor: pin.Model, n: int, seed: int) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """``n`` configurations of the 15 shared joints, as full q vectors of each model, uniform in both limits."""
    rng = np.random.default_rng(seed)
    names = [nm for nm in vendor.names[1:]]
    lo = np.array(
        [
            max(
                ours.lowerPositionLimit[ours.joints[ours.getJointId(nm)].idx_q],
                vendor.lowerPositionLimit[vendor.joints[vendor.getJointId(nm)].idx_q],
            )
            for nm in names
        ]
    )
    hi = np.array(
        [
            min(
                ours.upperPositionLimit[ours.joints[ours.getJointId(nm)].idx_q],
                vendor.upperPositionLimit[vendor.joints[vendor.getJointId(nm)].idx_q],
            )
            for nm in names
        ]
    )
    qs = rng.uniform(lo, hi, size=(n, len(names)))
    qo = np.zeros((n, ours.nq))
    qv = np.zeros((n, vendor.nq))
    for k, nm in enumerate(names):
        qo[:, ours.joints[ours.getJointId(nm)].idx_q] = qs[:, k]
        qv[:, vendor.joints[vendor.getJointId(nm)].idx_q] = qs[:, k]
    return qo, qv, names


def _frame_poses(model: pin.Model, qs: np.ndarray, frames: list[str]) -> np.ndarray:
    data = model.createData()
    ids = [model.getFrameId(f) for f in frames]
    out = np.empty((len(qs), len(frames), 4, 4))
    for i, q in enumerate(qs):
        pin.framesForwardKinematics(model, data, q)
        for j, fid in enumerate(ids):
            out[i, j] = data.oMf[fid].homogeneous
    return out


def _angle_deg(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    R = np.einsum("...ji,...jk->...ik", A[..., :3, :3], B[..., :3, :3])
    c = np.clip(0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0), -1.0, 1.0)
    return np.degrees(np.arccos(c))


def _geom_mesh(go: pin.GeometryObject) -> trimesh.Trimesh:
    g = go.geometry
    kind = type(g).__name__
    if kind == "Box":
        return trimesh.creation.box(extents=2.0 * np.asarray(g.halfSide))
    if kind == "Cylinder":
        return trimesh.creation.cylinder(radius=float(g.radius), height=2.0 * float(g.halfLength), sections=48)
    if kind == "Sphere":
        return trimesh.creation.icosphere(radius=float(g.radius))
    mesh = trimesh.load(go.meshPath, force="mesh")
    mesh.apply_scale(np.asarray(go.meshScale, dtype=float))
    return mesh


Placed = tuple[trimesh.Trimesh, int, np.ndarray, pin.GeometryObject]


def _link_meshes(model: pin.Model, geom: pin.GeometryModel) -> dict[str, list[Placed]]:
    """Link name -> [(mesh in its geometry frame, parent joint, placement in that joint's frame, the object)]."""
    out: dict[str, list[Placed]] = {}
    for go in geom.geometryObjects:
        link = model.frames[go.parentFrame].name
        out.setdefault(link, []).append((_geom_mesh(go), go.parentJoint, go.placement.homogeneous, go))
    return out


def _outside_distance(points: np.ndarray, prims: list[tuple[pin.GeometryObject, np.ndarray]]) -> np.ndarray:
    """Exact distance (metres) of world points outside the union of our boxes / cylinders (0 inside one)."""
    best = np.full(len(points), np.inf)
    for go, T in prims:
        local = (points - T[:3, 3]) @ T[:3, :3]
        g = go.geometry
        kind = type(g).__name__
        if kind == "Box":
            q = np.abs(local) - np.asarray(g.halfSide)
        elif kind == "Cylinder":
            q = np.stack(
                [np.linalg.norm(local[:, :2], axis=1) - float(g.radius), np.abs(local[:, 2]) - float(g.halfLength)],
                axis=1,
            )
        else:
            raise ValueError(f"our model has a {kind}; only boxes and cylinders are expected")
        best = np.minimum(best, np.linalg.norm(np.maximum(q, 0.0), axis=1))
    return best


def _samples(mesh: trimesh.Trimesh, n: int, seed: int) -> np.ndarray:
    pts, _ = trimesh.sample.sample_surface(mesh, n, seed=seed)
    return np.vstack([pts, mesh.vertices])


def compare(n: int, n_geom: int, n_samples: int, seed: int) -> dict[str, list[dict[str, object]]]:
    res = resolve_urdf(VENDOR)
    with_grip = vendor_urdf(VENDOR)
    mo, go = _models(URDF_PATH)
    mv = pin.buildModelFromUrdf(str(res.path))  # the vendor as shipped (no gripper): wrist poses, limits
    mg, gg = _models(with_grip)
    qo, qv, names = _configs(mo, mv, n, seed)
    # the vendor-with-gripper model has the same 15 joints plus 4 finger joints (left at 0 like ours)
    qg = np.zeros((n, mg.nq))
    for nm in names:
        qg[:, mg.joints[mg.getJointId(nm)].idx_q] = qv[:, mv.joints[mv.getJointId(nm)].idx_q]

    # 1. wrist and TCP poses
    fk_rows: list[dict[str, object]] = []
    for arm in ARMS:
        for label, frame, Ta, Tb in (
            (
                "wrist",
                f"{arm}_JOINT5_Link",
                _frame_poses(mo, qo, [f"{arm}_JOINT5_Link"]),
                _frame_poses(mv, qv, [f"{arm}_JOINT5_Link"]),
            ),
            (
                "tcp",
                f"{arm}_TCP_Link",
                _frame_poses(mo, qo, [f"{arm}_TCP_Link"]),
                _frame_poses(mg, qg, [f"{arm}_TCP_Link"]),
            ),
        ):
            dp = 1000.0 * np.linalg.norm(Ta[:, 0, :3, 3] - Tb[:, 0, :3, 3], axis=1)
            da = _angle_deg(Ta[:, 0], Tb[:, 0])
            fk_rows.append(
                {
                    "frame": frame,
                    "what": label,
                    "configs": n,
                    "pos_max_mm": float(dp.max()),
                    "pos_median_mm": float(np.median(dp)),
                    "ang_max_deg": float(da.max()),
                    "ang_median_deg": float(np.median(da)),
                }
            )

    # 2. joint limits
    lim_rows: list[dict[str, object]] = []
    for nm in names:
        jo, jv = mo.joints[mo.getJointId(nm)].idx_q, mv.joints[mv.getJointId(nm)].idx_q
        lim_rows.append(
            {
                "joint": nm,
                "ours_lower": float(mo.lowerPositionLimit[jo]),
                "ours_upper": float(mo.upperPositionLimit[jo]),
                "vendor_lower": float(mv.lowerPositionLimit[jv]),
                "vendor_upper": float(mv.upperPositionLimit[jv]),
                "max_abs_diff_rad": float(
                    max(
                        abs(mo.lowerPositionLimit[jo] - mv.lowerPositionLimit[jv]),
                        abs(mo.upperPositionLimit[jo] - mv.upperPositionLimit[jv]),
                    )
                ),
                "ours_velocity": float(mo.velocityLimit[mo.joints[mo.getJointId(nm)].idx_v]),
                "vendor_velocity": float(mv.velocityLimit[mv.joints[mv.getJointId(nm)].idx_v]),
            }
        )

    # 3. collision geometry per link, placed by each model's FK
    # the vendor's link geometry as the vendor option uses it: *ARM_JOINT5_Link cut at the flange (the chuck
    # hand beyond it is replaced by our gripper on both models, so the gripper links are not compared)
    lo_meshes, lv_meshes = _link_meshes(mo, go), _link_meshes(mg, gg)
    lv_meshes = {k: v for k, v in lv_meshes.items() if "GRIPPER" not in k and "FINGER" not in k}
    do, dv = mo.createData(), mg.createData()
    link_rows: list[dict[str, object]] = []
    for link in [lk for lk in lv_meshes if lk in lo_meshes]:
        # volumes in each link's own frame (placements are rigid)
        vo_parts = [m.copy().apply_transform(P) for m, _, P, _ in lo_meshes[link]]
        vo_union = trimesh.boolean.union(vo_parts, engine="manifold") if len(vo_parts) > 1 else vo_parts[0]
        vv = trimesh.util.concatenate([m.copy().apply_transform(P) for m, _, P, _ in lv_meshes[link]])
        hd, d_vo, d_ov, outside_frac, outside_max = [], [], [], [], []
        for i in range(min(n_geom, n)):
            pin.forwardKinematics(mo, do, qo[i])
            pin.forwardKinematics(mg, dv, qg[i])
            prims = [(m, do.oMi[j].homogeneous @ P, g) for m, j, P, g in lo_meshes[link]]
            po = np.vstack(
                [
                    trimesh.transform_points(_samples(m, n_samples // len(prims), seed + k), T)
                    for k, (m, T, _) in enumerate(prims)
                ]
            )
            pv = np.vstack(
                [
                    trimesh.transform_points(_samples(m, n_samples, seed), dv.oMi[j].homogeneous @ P)
                    for m, j, P, _ in lv_meshes[link]
                ]
            )
            a = cKDTree(po).query(pv)[0]  # vendor surface -> our surface
            b = cKDTree(pv).query(po)[0]  # our surface -> vendor surface
            out = _outside_distance(pv, [(g, T) for _, T, g in prims])  # exact, not sample-limited
            hd.append(max(a.max(), b.max()))
            d_vo.append(a.max())
            d_ov.append(b.max())
            outside_frac.append(float(np.mean(out > 1e-4)))
            outside_max.append(out.max())
        link_rows.append(
            {
                "link": link,
                "ours_shapes": len(lo_meshes[link]),
                "ours_union_volume_l": 1000.0 * vo_union.volume,
                "ours_hull_volume_l": 1000.0 * vo_union.convex_hull.volume,
                "vendor_hull_volume_l": 1000.0 * vv.convex_hull.volume,
                "vendor_faces": len(vv.faces),
                "hausdorff_mm": 1000.0 * max(hd),
                "vendor_to_ours_mm": 1000.0 * max(d_vo),
                "ours_to_vendor_mm": 1000.0 * max(d_ov),
                "vendor_outside_ours_pct": 100.0 * max(outside_frac),
                "vendor_outside_max_mm": 1000.0 * max(outside_max),
                "configs": min(n_geom, n),
            }
        )
    return {"fk": fk_rows, "limits": lim_rows, "links": link_rows}


def _write(rows: list[dict[str, object]], path: Path) -> None:
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})


def _print(title: str, rows: list[dict[str, object]]) -> None:
    print(f"\n## {title}")
    keys = list(rows[0])
    print(" | ".join(keys))
    for r in rows:
        print(" | ".join(f"{r[k]:.4g}" if isinstance(r[k], float) else str(r[k]) for k in keys))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--n", type=int, default=1000, help="random configurations for the FK comparison")
    ap.add_argument("--configs", type=int, default=5, help="of those, how many place the link geometry")
    ap.add_argument("--samples", type=int, default=20000, help="surface samples per link geometry")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    if not VENDOR.is_file():
        print(f"{VENDOR} is absent: the vendor's files live in ../shared/data", file=sys.stderr)
        return 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the xacro lines' warning: expected for this file
        result = compare(args.n, args.configs, args.samples, args.seed)
    OUT.mkdir(parents=True, exist_ok=True)
    for key, title in (
        ("fk", "wrist and TCP poses"),
        ("limits", "joint limits (rad, rad/s)"),
        ("links", "collision geometry per link (volumes in litres, distances in mm)"),
    ):
        _print(title, result[key])
        _write(result[key], OUT / f"nextage_vendor_{key}.csv")
    print(f"\nwrote {OUT}/nextage_vendor_{{fk,limits,links}}.csv")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
