"""Pose hypotheses from what the table tells: resting poses, and twins of the convex hull.

Two sources of hypotheses besides CVFH view matching, both built on the
paper's premise that a part lies at rest on the table:

* **Resting hypotheses.** A part at rest on the table takes one of its
  stable poses (:func:`stable_rests`), turned about the table
  normal and moved on the table: three unknowns instead of six. Each stable
  pose is tried at evenly spaced yaws, placed so the centroid of the model
  surface the camera would see falls on the observed cluster's centroid (in
  the table plane). The detector uses them when no CVFH hypothesis verifies,
  e.g. a peg lying with its head towards the camera, which shows a cube and
  hides its shank: the nearest rendered views all show the shank and none of
  their hypotheses comes within 50 deg.
* **Hull twins.** A rotation that maps the part's convex hull onto itself but
  not the part (a block with a blind hole turned over: same outside, hole on
  the other side) gives a second pose that explains every observed point on
  the outside equally well. A verified pose is tried again at each twin, and
  the twins are told apart only by the *disagreement evidence*: observed
  points that one pose explains (along the camera ray, the model surface is
  within ``fit`` of the point) and the other clearly does not (more than
  ``off`` away, e.g. the camera saw a plain face where the other pose has the
  hole). When neither pose has enough evidence against it, the view cannot
  tell them apart and the detection says so (``details["ambiguous"]``).

Frames: ``T_world_part`` 4x4, metres; the table frame has z along the
table normal, at the table height.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core import geometry
from asmteach.core.models import TablePlane
from asmteach.core.perception.registration import ModelCloud
from asmteach.core.perception.surface_check import ray_depths
from asmteach.core.rests.drops import drop_rests
from asmteach.core.rests.placements import plan_placements, resting_poses
from asmteach.core.symmetry import part_symmetries, principal_frame

import open3d as o3d  # isort: skip

__all__ = [
    "Disagreement",
    "disagreement",
    "every_rest",
    "hull_twins",
    "near_twins",
    "resting_hypotheses",
    "rests_near",
    "slide_on_table",
    "snap_to_rest",
    "stable_rests",
    "table_frame",
]


def stable_rests(mesh: trimesh.Trimesh, com: np.ndarray, max_poses: int) -> np.ndarray:
    """``(k, 4, 4)`` part poses resting on the plane z = 0, most likely first, footprint centred on x = y = 0.

    The rests are the part's placements (:mod:`asmteach.core.rests`, the ones
    the planners and the corrector use); their symmetry is not needed here.
    """
    placements = plan_placements(mesh, np.asarray(com, float), symmetry=False).placements
    return resting_poses(placements, np.asarray(mesh.vertices))[0][:max_poses]


def every_rest(mesh: trimesh.Trimesh, com: np.ndarray) -> np.ndarray:
    """``(k, 4, 4)`` part poses resting on the plane z = 0, one per convex-hull facet the centre of mass ``com``
    (part frame, metres) lies over, however small its margin or its chance (trimesh's stable poses, no threshold):
    every way the part can rest, where :func:`stable_rests` keeps the placements a drop is likely to end in."""
    return drop_rests(mesh, np.asarray(com, float))[0]


def hull_twins(mesh: trimesh.Trimesh, com: np.ndarray, own: list[np.ndarray] | None = None) -> list[np.ndarray]:
    """Rotations (``(4, 4)``, part frame) mapping the convex hull onto itself but not the part.

    One per class: two twins that differ by a symmetry of the part itself give
    the same pose and only the first is kept. ``own``: the part's symmetries
    when already known (:func:`part_symmetries`; a soccer ball's take 40 s).
    """
    hull = mesh.convex_hull
    own = [S[:3, :3] for S in (part_symmetries(mesh, np.asarray(com, float)) if own is None else own)]
    out: list[np.ndarray] = []
    for S in part_symmetries(hull, np.asarray(hull.center_mass, float)):
        R = S[:3, :3]
        # R and R' give the same pose when R' = R P for a symmetry P of the part.
        if any(np.allclose(R @ P, np.eye(3), atol=1e-6) for P in own):
            continue
        if any(np.allclose(Q[:3, :3] @ P, R, atol=1e-6) for Q in out for P in own):
            continue
        out.append(S)
    return out


def near_twins(
    mesh: trimesh.Trimesh,
    com: np.ndarray,
    tol: float,
    step_deg: float = 15.0,
    samples: int = 800,
    own: list[np.ndarray] | None = None,
) -> list[np.ndarray]:
    """Rotations (``(4, 4)``, part frame, about ``com``) that map the part *nearly* onto itself.

    A D-peg turned about its axis, a keyed peg with its key out of sight, a
    52 x 53 mm block turned by 90 deg: the turned part's surface stays within
    ``tol`` (mean distance, metres) of the part's, so a view that misses the
    small difference cannot tell the two poses apart, and verification alone
    (measured: the wrong pose scores within 0.01 of the right one) accepts
    either. Candidates: turns by multiples of ``step_deg`` about the three
    principal axes and the 24 turns of the cube group in the principal frame.
    Exact symmetries of the part (they give the same solid) are left out, as
    are candidates that differ from a kept one by one (``own``: the part's
    symmetries when already known).
    """
    com = np.asarray(com, float)
    own = [S[:3, :3] for S in (part_symmetries(mesh, com) if own is None else own)]
    F = principal_frame(mesh)
    cands = [F @ C @ F.T for C in Rotation.create_group("O").as_matrix()]
    for k in range(3):
        cands += [
            Rotation.from_rotvec(np.radians(a) * F[:, k]).as_matrix()
            for a in np.arange(step_deg, 360.0 - 1e-6, step_deg)
        ]
    pts, _ = trimesh.sample.sample_surface(mesh, samples, seed=0)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(mesh.vertices, np.float32)), o3d.core.Tensor(np.asarray(mesh.faces, np.uint32))
    )
    moved = np.einsum("cij,nj->cni", np.asarray(cands), pts - com) + com
    d = scene.compute_distance(o3d.core.Tensor(moved.reshape(-1, 3).astype(np.float32))).numpy()
    mean = d.reshape(len(cands), -1).mean(axis=1)
    out: list[np.ndarray] = []
    own_arr = np.asarray(own).reshape(-1, 3, 3)
    same = own_arr  # rotations giving a pose already covered: the part's symmetries, then kept twins times them
    for i in np.argsort(mean):
        R = cands[i]
        if mean[i] > tol:
            break
        if np.any(np.abs(same - R).max(axis=(1, 2)) < 1e-6):
            continue
        out.append(geometry.from_rotation(R, com - R @ com))
        same = np.concatenate([same, R @ own_arr])
    return out


def table_frame(table: TablePlane) -> np.ndarray:
    """``T_world_table``: z along the table normal, origin on the table below the world origin."""
    n = np.asarray(table.normal, float)
    n = n / np.linalg.norm(n)
    x = np.cross([0.0, 1.0, 0.0], n)
    if np.linalg.norm(x) < 1e-6:
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    return geometry.from_rotation(np.column_stack([x, np.cross(n, x), n]), n * table.height)


def resting_hypotheses(
    cluster: np.ndarray,
    model: ModelCloud,
    rests: np.ndarray,
    table: TablePlane,
    eye: np.ndarray,
    yaws: int,
    samples: int = 400,
) -> list[tuple[np.ndarray, float]]:
    """``(T_world_part, yaw)`` for every stable rest at ``yaws`` yaws, placed under the observed ``cluster``.

    ``cluster`` (n, 3) and ``eye`` (camera centre) are in the world frame. The
    model's camera-facing, unoccluded surface samples are moved onto the
    cluster's centroid in the table plane.
    """
    T_wt = table_frame(table)
    T_tw = geometry.invert(T_wt)
    c_t = geometry.transform_points(T_tw, cluster).mean(axis=0)
    step = max(1, len(model.points) // samples)
    pts, nrm = model.points[::step], model.normals[::step]
    poses = []
    for yaw in np.linspace(-np.pi, np.pi, yaws, endpoint=False):
        for R in rests:
            T = geometry.compose(T_wt, geometry.from_rotation(np.eye(3), [c_t[0], c_t[1], 0.0]), geometry.rot_z(yaw), R)
            poses.append((T, float(yaw)))
    Ts = np.asarray([T for T, _ in poses])
    # eye in each hypothesis' part frame; rays to every sample, one batched cast
    eyes = np.einsum("hij,j->hi", np.linalg.inv(Ts), np.append(eye, 1.0))[:, :3]
    d = pts[None] - eyes[:, None]
    dist = np.linalg.norm(d, axis=2)
    rays = np.concatenate([np.broadcast_to(eyes[:, None], d.shape), d / dist[..., None]], axis=2)
    hit = model.scene.cast_rays(o3d.core.Tensor(rays.reshape(-1, 6).astype(np.float32)))["t_hit"].numpy()
    seen = (hit.reshape(dist.shape) > dist - 1e-3) & (np.einsum("hnk,nk->hn", -d, nrm) > 0.0)
    out = []
    for (T, yaw), mask in zip(poses, seen, strict=True):
        if not mask.any():
            continue
        vis_t = geometry.transform_points(T_tw @ T, pts[mask]).mean(axis=0)
        shift = np.array([c_t[0] - vis_t[0], c_t[1] - vis_t[1], 0.0])
        out.append((T_wt @ geometry.from_rotation(np.eye(3), shift) @ T_tw @ T, yaw))
    return out


def snap_to_rest(
    T_world_part: np.ndarray, rests: np.ndarray, model: ModelCloud, table: TablePlane
) -> tuple[np.ndarray, float]:
    """``(T_world_part at the nearest stable rest, the turn to it in degrees)``.

    ``rests`` are :func:`stable_rests` (on z = 0 of the table frame). Of every rest turned about the table
    normal, the one whose rotation is nearest the pose's; the model's bounding-box centre stays where the
    pose puts it (in the table plane) and its lowest point is put on the table.
    """
    return rests_near(T_world_part, rests, model, table)[0]


def rests_near(
    T_world_part: np.ndarray, rests: np.ndarray, model: ModelCloud, table: TablePlane, limit_deg: float = np.inf
) -> list[tuple[np.ndarray, float]]:
    """``(T_world_part at a stable rest, the turn to it in degrees)`` for every rest within ``limit_deg``,
    nearest first.

    Each rest is turned about the table normal to the yaw nearest the pose's rotation; the model's
    bounding-box centre stays where the pose puts it (in the table plane) and its lowest point is put on the
    table (``rests``: :func:`stable_rests`, on z = 0 of the table frame).
    """
    T_wt = table_frame(table)
    T_tp = geometry.invert(T_wt) @ np.asarray(T_world_part, float)
    centre = T_tp[:3, :3] @ model.center + T_tp[:3, 3]
    out = []
    for rest in rests:
        M = T_tp[:3, :3] @ rest[:3, :3].T  # Rz(yaw) for a pose exactly at this rest
        # the yaw whose Rz is nearest M (the largest trace of Rz^T M): the turn to the rest is the least
        R = geometry.rot_z(float(np.arctan2(M[1, 0] - M[0, 1], M[0, 0] + M[1, 1])))[:3, :3] @ rest[:3, :3]
        deg = float(np.degrees(geometry.rotation_angle(R.T @ T_tp[:3, :3])))
        t = centre - R @ model.center
        t[2] -= float(np.min(model.hull_vertices @ R[2] + t[2]))
        out.append((T_wt @ geometry.from_rotation(R, t), deg))
    out.sort(key=lambda c: c[1])
    return [c for c in out if c[1] <= limit_deg]


def slide_on_table(
    T_world_part: np.ndarray,
    points: np.ndarray,
    model: ModelCloud,
    table: TablePlane,
    inlier: float,
    iterations: int = 10,
) -> np.ndarray:
    """``T_world_part`` moved on the table only (along it and turned about its normal) to fit the seen ``points``.

    A pose at a stable rest has its height and tilt from the table; the view gives the other three unknowns.
    Point-to-plane Gauss-Newton on those three: each seen point (world, metres) within ``inlier`` metres of the
    model pairs with its nearest model point and that point's normal. The rest's tilt and height are kept
    exactly; ICP, free in six, would tilt the pose again where the view does not pin it.
    """
    import open3d as o3d

    e1, e2, n = table_frame(table)[:3, :3].T  # two directions along the table, and its normal
    T = np.asarray(T_world_part, float).copy()
    pts = np.asarray(points, float)
    for _ in range(iterations):
        local = geometry.transform_points(geometry.invert(T), pts)
        near = model.scene.compute_closest_points(o3d.core.Tensor(local.astype(np.float32)))
        q_local = near["points"].numpy().astype(float)
        ok = np.linalg.norm(q_local - local, axis=1) < inlier
        if ok.sum() < 10:
            break
        q = geometry.transform_points(T, q_local[ok])
        nw = near["primitive_normals"].numpy().astype(float)[ok] @ T[:3, :3].T
        c = q.mean(axis=0)
        r = np.einsum("ij,ij->i", nw, pts[ok] - q)  # the seen point's distance along the model's normal
        J = np.column_stack([np.einsum("ij,ij->i", nw, np.cross(n, q - c)), nw @ e1, nw @ e2])
        (turn, a, b), *_ = np.linalg.lstsq(J, r, rcond=None)
        R = geometry.from_rotvec(turn * n)[:3, :3]
        T = geometry.from_rotation(R, c - R @ c + a * e1 + b * e2) @ T
        if abs(turn) < 1e-5 and np.hypot(a, b) < 1e-5:
            break
    return T


@dataclass(frozen=True)
class Disagreement:
    """Observed points each of two poses clearly fails to explain where the other explains them."""

    against_a: int
    against_b: int

    def verdict(self, min_points: int, ratio: float) -> str:
        """``"a"`` or ``"b"`` (the pose the evidence favours) or ``"ambiguous"``."""
        if self.against_b >= min_points and self.against_a * ratio <= self.against_b:
            return "a"
        if self.against_a >= min_points and self.against_b * ratio <= self.against_a:
            return "b"
        return "ambiguous"


def disagreement(
    T_a: np.ndarray, T_b: np.ndarray, cluster: np.ndarray, eye: np.ndarray, model: ModelCloud, fit: float, off: float
) -> Disagreement:
    """Count, for two poses, the cluster points each one is ``off`` (metres) from along the camera ray
    while the other is within ``fit``.

    The residual is measured along the ray from ``eye`` through the point (the
    depth the model predicts against the depth seen), not to the nearest
    surface: a plain face seen where a pose has a hole is 1-2 mm from the
    hole's rim but centimetres from the bottom the camera would see.
    """

    def residual(T: np.ndarray) -> np.ndarray:
        T_pw = geometry.invert(T)
        eye_local = geometry.transform_points(T_pw, np.asarray(eye, float)[None])[0]
        hit, dist = ray_depths(model, eye_local, geometry.transform_points(T_pw, cluster))
        return hit - dist  # inf where the ray misses the model

    ra, rb = np.abs(residual(T_a)), np.abs(residual(T_b))
    return Disagreement(int(np.sum((ra > off) & (rb < fit))), int(np.sum((rb > off) & (ra < fit))))
