"""Rotational symmetry of a part about a vertical axis through its centre of mass.

A part resting in a placement looks the same after a rotation by ``2 pi / m``
about the table normal through its COM when its shape has an ``m``-fold
symmetry about that axis; those yaws are *equivalent poses*. The symmetry
group about a fixed axis is cyclic, and a rotation by ``2 pi / k`` belongs to
it exactly when ``k`` divides ``m``, so the order is the largest ``k <=
max_order`` whose rotation maps the surface onto itself (within ``tol``).

Test: rotated hull vertices must land on hull vertices (a cheap necessary
condition, KD-tree), then rotated mesh vertices and face centroids must lie on
the mesh surface (Open3D ray-casting scene distance).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import open3d as o3d
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

__all__ = ["SymmetryFinder", "symmetry_yaws"]


def _surface_distance(mesh: trimesh.Trimesh) -> Callable[[np.ndarray], np.ndarray]:
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)),
    )

    def distance(points: np.ndarray) -> np.ndarray:
        return scene.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy().astype(float)

    return distance


class SymmetryFinder:
    """Finds the rotational symmetry order of a mesh about axes through one point.

    Parameters
    ----------
    mesh : the part's mesh (part frame, metres).
    hull_vertices : ``(k, 3)`` vertices of its convex hull.
    center : ``(3,)`` the point every axis passes through (the COM), metres.
    tol : metres; default ``1e-4`` of the mesh's largest extent.
    max_order : largest order tested.
    """

    def __init__(
        self,
        mesh: trimesh.Trimesh,
        hull_vertices: np.ndarray,
        center: np.ndarray,
        *,
        tol: float | None = None,
        max_order: int = 36,
    ) -> None:
        self.mesh = mesh
        self.center = np.asarray(center, dtype=float)
        extent = float(np.ptp(np.asarray(hull_vertices, dtype=float), axis=0).max())
        self.tol = float(tol) if tol is not None else 1e-4 * extent
        self.max_order = int(max_order)
        self.hull_pts = np.asarray(hull_vertices, dtype=float) - self.center
        self.hull_tree = cKDTree(self.hull_pts)
        self._surface_pts: np.ndarray | None = None
        self._distance: Callable[[np.ndarray], np.ndarray] | None = None

    def _surface_maps(self, R: np.ndarray) -> bool:
        if self._distance is None or self._surface_pts is None:
            self._distance = _surface_distance(self.mesh)
            v = np.asarray(self.mesh.vertices, dtype=float).view(np.ndarray)
            f = np.asarray(self.mesh.faces).view(np.ndarray)
            self._surface_pts = np.vstack([v, v[f].mean(axis=1)]) - self.center
        d = self._distance(self._surface_pts @ R.T + self.center)
        return bool(np.all(d <= self.tol))

    def order(self, axis: np.ndarray) -> int:
        """Symmetry order ``m >= 1`` about ``axis`` (part frame) through the centre."""
        axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
        ks = np.arange(self.max_order, 1, -1)
        rots = Rotation.from_rotvec(axis[None, :] * (2.0 * np.pi / ks)[:, None]).as_matrix()  # (K, 3, 3)
        # Necessary condition for every k at once: rotated hull vertices land on hull vertices.
        moved = np.einsum("kij,nj->kni", rots, self.hull_pts).reshape(-1, 3)
        d_hull, _ = self.hull_tree.query(moved, distance_upper_bound=2 * self.tol)
        ok = np.all(d_hull.reshape(len(ks), -1) <= self.tol, axis=1)
        for i in np.flatnonzero(ok):
            if self._surface_maps(rots[i]):
                return int(ks[i])
        return 1


def symmetry_yaws(order: int) -> list[float]:
    """The equivalent yaws ``2 pi j / m`` (radians) of an ``m``-fold symmetry, ``j = 0..m-1``."""
    return [2.0 * np.pi * j / order for j in range(order)]
