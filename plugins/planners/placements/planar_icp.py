"""Planar (3-DOF: x, y, yaw) ICP of a part model against an observed cloud.

Once a part is snapped to a stable placement its height, roll and pitch are
known exactly; only the position on the table and the yaw remain uncertain.
This ICP moves the model within the table plane only.

Two terms, both linearised in (x, y, yaw) and solved together by weighted
least squares each step:

* forward (cloud -> model): each observed point against the closest point on
  the model *surface* (Open3D ray-casting scene, exact point-to-triangle
  distance); point-to-plane rows (fast convergence, slide along faces) plus
  lightly weighted point-to-point rows in x, y;
* reverse (visible model -> cloud), when the camera centre is known: surface
  samples of the model that the camera can see at the current pose (facing
  it at less than ``max_incidence`` and not hidden by the part itself,
  ray-cast from the viewpoint) against their nearest observed point,
  point-to-point in x, y. A partial view leaves the model free to slide
  along an axis whose end faces are seen edge-on: the forward term only asks
  that every observed point lies on the model, not that every visible model
  surface was observed, so the model may overhang the observed ends. The
  reverse term penalises the overhang and pins that axis.

Nearest-neighbour correspondences converge slowly along such an axis (the
samples inside a face always find a near point and hold the model where it
is; only the few at the ends pull), so with a viewpoint the ICP ends with a
line search of the two-sided cost along the *weak axis*: the translation
direction the forward point-to-plane rows constrain least (smallest
eigenvalue of their Gauss-Newton matrix with the yaw eliminated), coarse then
fine, the minimum placed by a parabola.

Huber weights and a correspondence distance that shrinks from
``max_correspondence`` to ``min_correspondence`` trim outliers in both terms.

Frames: everything is in the table frame (z = table normal, metres, radians);
the yaw is a rotation about the table normal through the matched points' centroid.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import open3d as o3d
import trimesh
from scipy.spatial import cKDTree

__all__ = ["ModelSurface", "PlanarIcpResult", "planar_icp", "planar_transform"]


class ModelSurface:
    """Closest-point and visibility queries on a mesh surface (part frame, metres).

    ``samples`` evenly spread surface points (seeded) with their face normals
    stand for the model's surface in the reverse (model -> cloud) term.
    """

    def __init__(self, mesh: trimesh.Trimesh, *, samples: int = 6000, seed: int = 0) -> None:
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(
            o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
            o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)),
        )
        pts, faces = trimesh.sample.sample_surface_even(mesh, samples, seed=seed)
        if len(pts) < samples // 2:  # even sampling rejects many on thin parts; top up uniformly
            more, more_faces = trimesh.sample.sample_surface(mesh, samples - len(pts), seed=seed + 1)
            pts, faces = np.vstack([pts, more]), np.concatenate([faces, more_faces])
        self.samples = np.asarray(pts, dtype=float)
        self.sample_normals = np.asarray(mesh.face_normals, dtype=float)[faces]

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Closest surface points and the unit normals of their triangles, both ``(n, 3)``."""
        ans = self.scene.compute_closest_points(o3d.core.Tensor(np.asarray(points, dtype=np.float32)))
        return ans["points"].numpy().astype(float), ans["primitive_normals"].numpy().astype(float)

    def visible_index(
        self, T_frame_part: np.ndarray, eye: np.ndarray, max_incidence: float = np.radians(70.0)
    ) -> np.ndarray:
        """Indices of the surface samples the camera at ``eye`` sees with the part at ``T_frame_part``.

        ``eye`` is in the frame of ``T_frame_part`` (metres). A sample is seen
        when its face turns towards the camera at an incidence below
        ``max_incidence`` (radians; a depth sensor loses grazing returns) and
        the ray from ``eye`` reaches it before any other part of the mesh.
        """
        R, t = T_frame_part[:3, :3], T_frame_part[:3, 3]
        eye_p = R.T @ (np.asarray(eye, dtype=float) - t)
        to_eye = eye_p - self.samples
        dist = np.linalg.norm(to_eye, axis=1)
        idx = np.flatnonzero(np.einsum("ij,ij->i", self.sample_normals, to_eye) > np.cos(max_incidence) * dist)
        if len(idx) == 0:
            return idx
        rays = np.hstack([np.repeat(eye_p[None], len(idx), axis=0), -to_eye[idx] / dist[idx, None]])
        hit = self.scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy()
        return idx[hit > dist[idx] - 5e-4]  # float32 ray casting: half a millimetre of slack

    def visible(self, T_frame_part: np.ndarray, eye: np.ndarray, max_incidence: float = np.radians(70.0)) -> np.ndarray:
        """The visible samples (see :meth:`visible_index`), ``(k, 3)`` in the frame of ``T_frame_part``."""
        idx = self.visible_index(T_frame_part, eye, max_incidence)
        return self.samples[idx] @ T_frame_part[:3, :3].T + T_frame_part[:3, 3]


@dataclass
class PlanarIcpResult:
    """Outcome of :func:`planar_icp`.

    ``T_table_part``: refined pose; ``dx, dy`` (metres) and ``dyaw`` (radians) the total
    planar motion applied; ``fitness``: fraction of cloud points within
    ``min_correspondence`` of the model (higher is better); ``rmse``: RMS distance of
    those inliers, metres (lower is better); ``cost``: mean squared distance truncated
    at ``2 * min_correspondence``, cloud to model plus (with a viewpoint) visible model
    to cloud, to rank starts (lower is better); ``coverage``: fraction of the visible
    model samples within ``min_correspondence`` of an observed point (NaN without a
    viewpoint; higher is better).
    """

    T_table_part: np.ndarray
    dx: float
    dy: float
    dyaw: float
    fitness: float
    rmse: float
    cost: float
    iterations: int
    converged: bool
    coverage: float = float("nan")
    weak_axis: np.ndarray | None = None
    """(2,) unit x, y direction of the line search (None: no search)."""
    weak_shift: float = 0.0
    """Metres moved along ``weak_axis`` by the line search."""


def planar_transform(dx: float, dy: float, dyaw: float, pivot: np.ndarray) -> np.ndarray:
    """``(4, 4)`` rotation by ``dyaw`` about the z axis through ``pivot`` (x, y), then translation."""
    c, s = np.cos(dyaw), np.sin(dyaw)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    p = np.asarray(pivot, dtype=float)[:2]
    T[:2, 3] = p - T[:2, :2] @ p + np.array([dx, dy])
    return T


def _huber(r: np.ndarray, k: float) -> np.ndarray:
    a = np.abs(r)
    return np.where(a <= k, 1.0, k / np.maximum(a, 1e-300))


def _point_rows(m: np.ndarray, diff: np.ndarray, pivot: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted x and y point-to-point rows: ``diff_xy ~ t + theta * ez x (m - pivot)``."""
    lever = m[:, :2] - pivot
    ones, zeros = np.ones(len(m)), np.zeros(len(m))
    J = np.vstack([np.column_stack([ones, zeros, -lever[:, 1]]), np.column_stack([zeros, ones, lever[:, 0]])])
    r = np.concatenate([diff[:, 0], diff[:, 1]])
    ww = np.concatenate([w, w])
    return J * ww[:, None], r * ww


def planar_icp(
    surface: ModelSurface,
    T_table_part: np.ndarray,
    cloud_table: np.ndarray,
    *,
    max_correspondence: float = 0.02,
    min_correspondence: float = 0.003,
    max_iterations: int = 40,
    point_weight: float = 0.2,
    viewpoint: np.ndarray | None = None,
    reverse_weight: float = 1.0,
    max_incidence: float = np.radians(70.0),
    line_search: float = 0.004,
    tolerance: float = 1e-5,
) -> PlanarIcpResult:
    """Refine x, y and yaw of ``T_table_part`` so the model surface fits ``cloud_table``.

    Parameters
    ----------
    surface : the part's model surface (part frame).
    T_table_part : ``(4, 4)`` start pose in the table frame; its height, roll and pitch are kept.
    cloud_table : ``(n, 3)`` observed points of the part in the table frame, metres.
    max_correspondence, min_correspondence : metres; the inlier radius shrinks from the first
        to the second over the iterations.
    max_iterations : Gauss-Newton steps.
    point_weight : weight of the forward x, y point-to-point rows relative to the point-to-plane rows.
    viewpoint : ``(3,)`` camera centre in the table frame (metres); enables the reverse term.
    reverse_weight : total weight of the reverse term relative to the forward point-to-plane term.
    max_incidence : radians; model surface seen more obliquely than this is not expected in the cloud.
    line_search : metres; half-range of the final weak-axis line search (0: none; needs ``viewpoint``).
    tolerance : stop when a step moves less than this (metres, and radians times 0.1 m).
    """
    T = np.asarray(T_table_part, dtype=float).copy()
    cloud = np.asarray(cloud_table, dtype=float).reshape(-1, 3)
    tree = cKDTree(cloud) if viewpoint is not None and len(cloud) else None
    eye = None if viewpoint is None else np.asarray(viewpoint, dtype=float)
    total = np.eye(4)
    converged = False
    it = 0
    k = max(min_correspondence / 3.0, 1e-4)
    # Which samples are visible hardly changes over the few millimetres and degrees an ICP moves: decide once.
    vis_idx = surface.visible_index(T, eye, max_incidence) if eye is not None else None
    for it in range(1, max_iterations + 1):
        radius = max(min_correspondence, max_correspondence * 0.75 ** (it - 1))
        R, t = T[:3, :3], T[:3, 3]
        cp_part, n_part = surface.closest((cloud - t) @ R)
        m = cp_part @ R.T + t
        nw = n_part @ R.T
        diff = cloud - m
        inl = np.linalg.norm(diff, axis=1) < radius
        if inl.sum() < 6:
            break
        m, nw, diff = m[inl], nw[inl], diff[inl]
        pivot = m[:, :2].mean(axis=0)
        lever = m[:, :2] - pivot
        # Forward point-to-plane rows: n . (c - m) ~ n . (t + theta * ez x (m - pivot)).
        r_pl = np.einsum("ij,ij->i", nw, diff)
        J_pl = np.column_stack([nw[:, 0], nw[:, 1], -nw[:, 0] * lever[:, 1] + nw[:, 1] * lever[:, 0]])
        w_pl = _huber(r_pl, k)
        blocks_J = [J_pl * w_pl[:, None]]
        blocks_r = [r_pl * w_pl]
        J_pt, r_pt = _point_rows(m, diff, pivot, point_weight * _huber(np.linalg.norm(diff[:, :2], axis=1), k))
        blocks_J.append(J_pt)
        blocks_r.append(r_pt)
        if tree is not None and vis_idx is not None:
            vis = surface.samples[vis_idx] @ R.T + t
            if len(vis):
                d_rev, j = tree.query(vis)
                keep = d_rev < radius
                if keep.any():
                    mv, dv = vis[keep], cloud[j[keep]] - vis[keep]
                    # Scaled so the reverse term weighs like the forward one whatever the two counts.
                    scale = reverse_weight * np.sqrt(len(m) / keep.sum())
                    J_rv, r_rv = _point_rows(mv, dv, pivot, scale * _huber(np.linalg.norm(dv[:, :2], axis=1), k))
                    blocks_J.append(J_rv)
                    blocks_r.append(r_rv)
        delta, *_ = np.linalg.lstsq(np.vstack(blocks_J), np.concatenate(blocks_r), rcond=None)
        step = planar_transform(delta[0], delta[1], delta[2], pivot)
        T = step @ T
        total = step @ total
        if np.linalg.norm(delta[:2]) < tolerance and abs(delta[2]) * 0.1 < tolerance:
            converged = True
            break
    axis, shift = None, 0.0
    if tree is not None and eye is not None and line_search > 0.0 and it > 0:
        axis = _weak_axis(surface, T, cloud, min_correspondence, k)
        if axis is not None:
            idx = surface.visible_index(T, eye, max_incidence)  # one visible set: a smooth cost along the axis
            T, shift = _line_search(
                lambda T_: _scores(surface, T_, cloud, tree, eye, min_correspondence, max_incidence, idx)[2],
                T,
                axis,
                line_search,
            )
            total = planar_transform(axis[0] * shift, axis[1] * shift, 0.0, np.zeros(2)) @ total
    fitness, rmse, cost, coverage = _scores(surface, T, cloud, tree, eye, min_correspondence, max_incidence)
    dyaw = float(np.arctan2(total[1, 0], total[0, 0]))
    return PlanarIcpResult(
        T_table_part=T,
        dx=float(T[0, 3] - T_table_part[0, 3]),
        dy=float(T[1, 3] - T_table_part[1, 3]),
        dyaw=dyaw,
        fitness=fitness,
        rmse=rmse,
        cost=cost,
        iterations=it,
        converged=converged,
        coverage=coverage,
        weak_axis=axis,
        weak_shift=shift,
    )


def _weak_axis(surface: ModelSurface, T: np.ndarray, cloud: np.ndarray, radius: float, k: float) -> np.ndarray | None:
    """Unit (x, y) direction the forward point-to-plane rows constrain least at pose ``T``, or None."""
    R, t = T[:3, :3], T[:3, 3]
    cp_part, n_part = surface.closest((cloud - t) @ R)
    m = cp_part @ R.T + t
    nw = n_part @ R.T
    diff = cloud - m
    inl = np.linalg.norm(diff, axis=1) < radius
    if inl.sum() < 6:
        return None
    m, nw = m[inl], nw[inl]
    w = _huber(np.einsum("ij,ij->i", nw, diff[inl]), k) ** 2
    lever = m[:, :2] - m[:, :2].mean(axis=0)
    J = np.column_stack([nw[:, 0], nw[:, 1], -nw[:, 0] * lever[:, 1] + nw[:, 1] * lever[:, 0]])
    H = (J * w[:, None]).T @ J
    # Eliminate the yaw (Schur complement): how well x, y are held when the yaw may follow.
    H_tt = H[:2, :2] - np.outer(H[:2, 2], H[2, :2]) / max(H[2, 2], 1e-12)
    _, vecs = np.linalg.eigh(H_tt)
    return vecs[:, 0]


def _line_search(
    cost: Callable[[np.ndarray], float], T: np.ndarray, axis: np.ndarray, half_range: float
) -> tuple[np.ndarray, float]:
    """Move ``T`` along the table-plane ``axis`` to the minimum of ``cost`` within ``+-half_range`` metres.

    A coarse grid (9 points), a fine grid (quarter steps) around its best
    point, and the vertex of a least-squares parabola through the fine grid
    when it is convex and inside it. Returns the pose and the shift (metres).
    """

    def at(s: float) -> np.ndarray:
        out = T.copy()
        out[:2, 3] += axis * s
        return out

    coarse = np.linspace(-half_range, half_range, 9)
    c_coarse = [cost(at(s)) for s in coarse]
    best = float(coarse[int(np.argmin(c_coarse))])
    h = (coarse[1] - coarse[0]) / 4.0
    fine = best + h * np.arange(-3, 4)
    c_fine = np.array([c_coarse[int(np.argmin(c_coarse))] if i == 3 else cost(at(s)) for i, s in enumerate(fine)])
    a, b, _ = np.polyfit(fine, c_fine, 2)
    shift = float(fine[int(np.argmin(c_fine))])
    if a > 0 and fine[0] <= -b / (2 * a) <= fine[-1]:
        shift = float(-b / (2 * a))
    return at(shift), shift


def _scores(
    surface: ModelSurface,
    T: np.ndarray,
    cloud: np.ndarray,
    tree: cKDTree | None,
    eye: np.ndarray | None,
    inlier: float,
    max_incidence: float,
    vis_idx: np.ndarray | None = None,
) -> tuple[float, float, float, float]:
    """Fitness, inlier RMSE, truncated cost and visible-surface coverage of pose ``T`` (see the result).

    ``vis_idx`` fixes the visible samples; ``None`` finds them at ``T``.
    """
    R, t = T[:3, :3], T[:3, 3]
    cp_part, _ = surface.closest((cloud - t) @ R)
    dist = np.linalg.norm(cloud - (cp_part @ R.T + t), axis=1)
    inl = dist < inlier
    fitness = float(inl.mean()) if len(dist) else 0.0
    rmse = float(np.sqrt(np.mean(dist[inl] ** 2))) if inl.any() else float("inf")
    # Truncated at twice the final inlier radius: far outliers all cost the same.
    cost = float(np.mean(np.minimum(dist, 2.0 * inlier) ** 2)) if len(dist) else float("inf")
    coverage = float("nan")
    if tree is not None and eye is not None:
        idx = surface.visible_index(T, eye, max_incidence) if vis_idx is None else vis_idx
        vis = surface.samples[idx] @ R.T + t
        if len(vis):
            d_rev, _ = tree.query(vis)
            coverage = float(np.mean(d_rev < inlier))
            cost += float(np.mean(np.minimum(d_rev, 2.0 * inlier) ** 2))
    return fitness, rmse, cost, coverage
