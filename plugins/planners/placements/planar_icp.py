"""Planar (3-DOF: x, y, yaw) ICP of a part model against an observed cloud.

Once a part is snapped to a stable placement its height, roll and pitch are
known exactly; only the position on the table and the yaw remain uncertain.
This ICP moves the model within the table plane only. Correspondences are
the closest points on the model *surface* (Open3D ray-casting scene, exact
point-to-triangle distance), so a partial view matches the visible faces.

Each step solves a linearised least-squares problem mixing point-to-plane
rows (fast convergence, slides along faces) with lightly weighted
point-to-point rows in x, y (keeps the problem well posed when the visible
faces are all horizontal), with Huber weights and a correspondence distance
that shrinks from ``max_correspondence`` to ``min_correspondence``.

Frames: everything is in the table frame (z = table normal, metres, radians);
the yaw is a rotation about the table normal through the model's centroid.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
import trimesh

__all__ = ["ModelSurface", "PlanarIcpResult", "planar_icp", "planar_transform"]


class ModelSurface:
    """Closest-point queries on a mesh surface (part frame, metres)."""

    def __init__(self, mesh: trimesh.Trimesh) -> None:
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(
            o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
            o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)),
        )

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Closest surface points and the unit normals of their triangles, both ``(n, 3)``."""
        ans = self.scene.compute_closest_points(o3d.core.Tensor(np.asarray(points, dtype=np.float32)))
        return ans["points"].numpy().astype(float), ans["primitive_normals"].numpy().astype(float)


@dataclass
class PlanarIcpResult:
    """Outcome of :func:`planar_icp`.

    ``T_table_part``: refined pose; ``dx, dy`` (metres) and ``dyaw`` (radians) the total
    planar motion applied (yaw about the model centroid); ``fitness``: fraction of
    cloud points within ``min_correspondence`` of the model (higher is better);
    ``rmse``: RMS distance of those inliers, metres (lower is better); ``cost``:
    mean squared distance truncated at ``2 * min_correspondence``, to rank starts (lower is better).
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


def planar_icp(
    surface: ModelSurface,
    T_table_part: np.ndarray,
    cloud_table: np.ndarray,
    *,
    max_correspondence: float = 0.02,
    min_correspondence: float = 0.003,
    max_iterations: int = 40,
    point_weight: float = 0.2,
    tolerance: float = 1e-6,
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
    point_weight : weight of the x, y point-to-point rows relative to the point-to-plane rows.
    tolerance : stop when a step moves less than this (metres, and radians times 0.1 m).
    """
    T = np.asarray(T_table_part, dtype=float).copy()
    cloud = np.asarray(cloud_table, dtype=float).reshape(-1, 3)
    total = np.eye(4)
    converged = False
    it = 0
    for it in range(1, max_iterations + 1):
        radius = max(min_correspondence, max_correspondence * 0.75 ** (it - 1))
        R, t = T[:3, :3], T[:3, 3]
        cp_part, n_part = surface.closest((cloud - t) @ R)
        m = cp_part @ R.T + t
        nw = n_part @ R.T
        diff = cloud - m
        dist = np.linalg.norm(diff, axis=1)
        inl = dist < radius
        if inl.sum() < 6:
            break
        m, nw, diff = m[inl], nw[inl], diff[inl]
        pivot = m[:, :2].mean(axis=0)
        lever = m[:, :2] - pivot
        # Point-to-plane rows: n . (c - m) ~ n . (t + theta * ez x (m - pivot)).
        r_pl = np.einsum("ij,ij->i", nw, diff)
        J_pl = np.column_stack([nw[:, 0], nw[:, 1], -nw[:, 0] * lever[:, 1] + nw[:, 1] * lever[:, 0]])
        # Point-to-point rows in x and y.
        ones, zeros = np.ones(len(m)), np.zeros(len(m))
        J_px = np.column_stack([ones, zeros, -lever[:, 1]])
        J_py = np.column_stack([zeros, ones, lever[:, 0]])
        k = max(min_correspondence / 3.0, 1e-4)
        w_pl = _huber(r_pl, k)
        w_pt = point_weight * _huber(np.linalg.norm(diff[:, :2], axis=1), k)
        J = np.vstack([J_pl * w_pl[:, None], J_px * w_pt[:, None], J_py * w_pt[:, None]])
        r = np.concatenate([r_pl * w_pl, diff[:, 0] * w_pt, diff[:, 1] * w_pt])
        delta, *_ = np.linalg.lstsq(J, r, rcond=None)
        step = planar_transform(delta[0], delta[1], delta[2], pivot)
        T = step @ T
        total = step @ total
        if np.linalg.norm(delta[:2]) < tolerance and abs(delta[2]) * 0.1 < tolerance:
            converged = True
            break
    R, t = T[:3, :3], T[:3, 3]
    cp_part, _ = surface.closest((cloud - t) @ R)
    dist = np.linalg.norm(cloud - (cp_part @ R.T + t), axis=1)
    inl = dist < min_correspondence
    fitness = float(inl.mean()) if len(dist) else 0.0
    rmse = float(np.sqrt(np.mean(dist[inl] ** 2))) if inl.any() else float("inf")
    # Truncated at twice the final inlier radius: far outliers all cost the same.
    cost = float(np.mean(np.minimum(dist, 2.0 * min_correspondence) ** 2)) if len(dist) else float("inf")
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
    )
