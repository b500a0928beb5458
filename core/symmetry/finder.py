"""The order of a mesh's rotational symmetry about an axis (:class:`SymmetryFinder`), and whether one
rotation maps it onto itself.

How a rotation is tested (``SymmetryFinder.maps``), from cheap necessary
conditions to the full one, so most candidates cost a few KD-tree queries:

1. the hull vertex farthest from an axis has a hull vertex on its circle at
   the angle ``2 pi / k`` (one pass over the hull vertices gives every
   candidate ``k``), then, on meshes with many vertices, every rotated hull
   vertex lands on a hull vertex (KD-tree, candidates only);
2. when every rotated mesh vertex lands on a mesh vertex and the faces map
   onto faces, the mesh itself is symmetric and the rotation is accepted;
3. rotated sharp corners of the mesh (vertices whose face normals span 3-D:
   any tessellation of the surface has a vertex there) must land on mesh
   vertices and rotated hull vertices on hull vertices, else it is refused;
4. otherwise (a symmetric shape tessellated asymmetrically) the rotated mesh
   vertices and face centroids that did not land on vertices and faces must
   lie on the mesh surface: exact point-triangle distances to the faces whose
   planes pass within ``tol`` (double precision; Open3D's float32 scene
   distance put the centroids of long slivers 2 ``tol`` off their own faces).

Units: metres, radians; frames: the part frame.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from asmteach.core import geometry

# A vertex is a sharp corner when the smallest eigenvalue of the mean n n^T of its faces'
# unit normals exceeds this (0 on a plane or a crease; 1/3 at a box corner).
_CORNER_EIG = 0.02
# Meshes with at most this many vertices skip the hull-vertex prefilter of the candidate orders.
_SMALL = 64
# Point-plane distances computed per chunk of points (bounds the memory of the on-surface test).
_PAIRS = 2_000_000


def axis_rotations(axis: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """``(K, 3, 3)`` rotations by ``angles`` (radians) about the unit ``axis`` (Rodrigues' formula)."""
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    c, s = np.cos(angles)[:, None, None], np.sin(angles)[:, None, None]
    skew = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return c * np.eye(3) + s * skew + (1.0 - c) * np.outer(a, a)


def _within(points: np.ndarray, triangles: np.ndarray, normals: np.ndarray, tol: float) -> np.ndarray:
    """``(n,) bool``: each point lies within ``tol`` (m) of its triangle (``(n, 3, 3)``, unit ``(n, 3)`` normals).

    Exact: inside the triangle's prism the distance is the one to its plane;
    outside, the one to the nearest of its three edges (segments), computed
    only for the points the prism test leaves undecided.
    """
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    plane = np.abs(np.einsum("ij,ij->i", points - a, normals))
    inside = np.ones(len(points), dtype=bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", geometry.cross(v - u, points - u), normals) >= 0.0
    hit = inside & (plane <= tol)
    rest = np.flatnonzero(~inside)
    if len(rest):
        p, edge = points[rest], np.full(len(rest), np.inf)
        for u, v in ((a[rest], b[rest]), (b[rest], c[rest]), (c[rest], a[rest])):
            uv, up = v - u, p - u
            t = np.clip(np.einsum("ij,ij->i", up, uv) / np.einsum("ij,ij->i", uv, uv), 0.0, 1.0)
            edge = np.minimum(edge, np.linalg.norm(up - t[:, None] * uv, axis=1))
        hit[rest] = edge <= tol
    return hit


def _face_keys(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """One integer per face for its set of vertex ids (any winding, any starting vertex)."""
    rows = np.sort(faces, axis=1).astype(object if n_vertices >= 2_000_000 else np.int64)
    return (rows[:, 0] * n_vertices + rows[:, 1]) * n_vertices + rows[:, 2]


class SymmetryFinder:
    """Finds the rotational symmetry order of a mesh about axes through one point.

    Parameters
    ----------
    mesh : the part's mesh (part frame, metres).
    hull_vertices : ``(k, 3)`` vertices of its convex hull.
    center : ``(3,)`` the point every axis passes through (the COM), metres.
    tol : metres; default ``1e-4`` of the mesh's largest extent.
    max_order : largest order tested.
    corners : refuse a rotation that takes a sharp corner of the mesh off every mesh vertex (step 3 of
        the module docstring). Right for exact symmetry (a ``tol`` far below the edge lengths); with a
        ``tol`` of the order of a tessellated circle's edges, the rim vertices of a 64-sided cylinder
        are "corners" that a turn by 120 deg moves between vertices although the surface maps within
        ``tol``, so :func:`part_symmetries` turns it off and relies on the surface test alone.
    """

    def __init__(
        self,
        mesh: trimesh.Trimesh,
        hull_vertices: np.ndarray,
        center: np.ndarray,
        *,
        tol: float | None = None,
        max_order: int = 36,
        corners: bool = True,
    ) -> None:
        self.center = np.asarray(center, dtype=float)
        self.hull_pts = np.asarray(hull_vertices, dtype=float) - self.center
        extent = float(np.ptp(self.hull_pts, axis=0).max())
        self.tol = float(tol) if tol is not None else 1e-4 * extent
        self.max_order = int(max_order)
        self.corners = bool(corners)
        self.hull_tree = cKDTree(self.hull_pts)
        # Plain arrays: trimesh's tracked arrays re-hash on access.
        self.vertices = np.asarray(mesh.vertices, dtype=float).view(np.ndarray) - self.center
        self.faces = np.asarray(mesh.faces, dtype=np.int64).view(np.ndarray)
        self._tree: cKDTree | None = None
        self._face_keys: np.ndarray | None = None
        self._corners: np.ndarray | None = None
        self._planes: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._scene: Any = None

    def _sharp_corners(self) -> np.ndarray:
        """Ids of the mesh vertices whose incident face normals span 3-D (see ``_CORNER_EIG``)."""
        tri = self.vertices[self.faces]
        n = geometry.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        length = np.linalg.norm(n, axis=1)
        ok = length > 0.0
        n = n[ok] / length[ok, None]
        outer = (n[:, :, None] * n[:, None, :]).reshape(-1, 9)
        ids = self.faces[ok].reshape(-1)
        n_v = len(self.vertices)
        # Sum n n^T over each vertex's faces, one bincount per matrix entry.
        scatter = np.stack(
            [np.bincount(ids, weights=np.repeat(outer[:, j], 3), minlength=n_v) for j in range(9)], axis=1
        ).reshape(n_v, 3, 3)
        count = np.bincount(ids, minlength=n_v).astype(float)
        used = count > 0
        smallest = np.zeros(len(self.vertices))
        smallest[used] = np.linalg.eigvalsh(scatter[used] / count[used, None, None])[:, 0]
        return np.flatnonzero(smallest > _CORNER_EIG)

    def _on_surface(self, points: np.ndarray) -> bool:
        """Whether every centred point lies within ``tol`` of the mesh surface (stops at the first miss).

        Exact, without a spatial index: a point within ``tol`` of the surface
        is within ``tol`` of the plane of its nearest face, so only the faces
        whose planes pass that close (one matrix product) get the exact
        point-triangle test. Without the corner test (a loose ``tol``), an
        Open3D BVH distance query (float32: nanometres on a part, far below
        such a ``tol``) does it at a fraction of the cost.
        """
        if not self.corners:
            return self._on_surface_bvh(points)
        if self._planes is None:
            tri = self.vertices[self.faces]
            n = geometry.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            length = np.linalg.norm(n, axis=1)
            keep = np.flatnonzero(length > 0.0)  # zero-area faces add no surface
            n = n[keep] / length[keep, None]
            self._planes = (keep, n, np.einsum("ij,ij->i", n, tri[keep, 0]))
        keep, normals, offsets = self._planes
        step = max(1, _PAIRS // max(len(keep), 1))
        for start in range(0, len(points), step):
            pts = points[start : start + step]
            near_p, near_f = np.nonzero(np.abs(pts @ normals.T - offsets) <= self.tol)
            hit = np.zeros(len(pts), dtype=bool)
            hit[near_p] = True
            if not hit.all():
                return False  # some point is off every face plane
            close = _within(pts[near_p], self.vertices[self.faces[keep[near_f]]], normals[near_f], self.tol)
            hit[:] = False
            hit[near_p[close]] = True
            if not hit.all():
                return False
        return True

    def maps(self, R: np.ndarray) -> bool:
        """Whether the rotation ``R`` (about the centre) maps the mesh surface onto itself within ``tol``.

        Rotated mesh vertices and face centroids must lie on the surface. A
        vertex that lands on a vertex does; a face whose vertices land on the
        vertices of one mesh face does too; only the rest need a distance.
        """
        if self._tree is None:
            self._tree = cKDTree(self.vertices)
            self._face_keys = np.sort(_face_keys(self.faces, len(self.vertices)))
        moved = self.vertices @ R.T
        d, idx = self._tree.query(moved, distance_upper_bound=2.0 * self.tol)
        landed = d <= self.tol
        face_landed = np.all(landed[self.faces], axis=1)
        matched = face_landed.copy()
        keys = _face_keys(idx[self.faces[face_landed]], len(self.vertices))
        at = np.minimum(np.searchsorted(self._face_keys, keys), len(self._face_keys) - 1)
        matched[face_landed] = self._face_keys[at] == keys
        if np.all(matched):
            return True  # the rotation permutes the mesh's own vertices and faces
        if self.corners and not np.all(landed):
            if self._corners is None:
                self._corners = self._sharp_corners()
            if not np.all(landed[self._corners]):
                return False  # a sharp corner must land on a corner of the surface, i.e. on a vertex
            if not self._hull_maps(R[None])[0]:
                return False
        rest = np.vstack([moved[~landed], moved[self.faces[~matched]].mean(axis=1)])
        # Early exit: the first few points (unlanded vertices first) refute most wrong rotations.
        head = 16
        if len(rest) > head and not self._on_surface(rest[:head]):
            return False
        return self._on_surface(rest)

    def _hull_maps(self, rots: np.ndarray) -> np.ndarray:
        """``(K,) bool``: each rotation takes every hull vertex onto a hull vertex within ``tol``."""
        moved = np.matmul(rots, self.hull_pts.T).transpose(0, 2, 1).reshape(-1, 3)
        d, _ = self.hull_tree.query(moved, distance_upper_bound=2.0 * self.tol)
        return np.all(d.reshape(len(rots), -1) <= self.tol, axis=1)

    def candidate_orders(self, axis: np.ndarray) -> np.ndarray:
        """Orders ``k`` (descending) whose rotation takes the hull vertex farthest from ``axis`` onto a hull vertex.

        A symmetry moves that vertex ``p`` along its circle about the axis, so
        some hull vertex at the same radius and height must sit at the angle
        ``2 pi / k`` from it (within ``tol`` along the circle): a necessary
        condition that costs one pass over the hull vertices.
        """
        axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
        height = self.hull_pts @ axis
        radial = self.hull_pts - np.outer(height, axis)
        radius = np.linalg.norm(radial, axis=1)
        i = int(np.argmax(radius))
        r0 = float(radius[i])
        ring = (np.abs(radius - r0) <= self.tol) & (np.abs(height - height[i]) <= self.tol)
        ring[i] = False
        ks = np.arange(self.max_order, 1, -1)
        if not ring.any() or r0 <= self.tol:
            return ks[:0]
        u = radial[i] / r0
        v = geometry.cross(axis, u)
        theta = np.mod(np.arctan2(radial[ring] @ v, radial[ring] @ u), 2.0 * np.pi)
        gap = np.abs(2.0 * np.pi / ks[:, None] - theta[None, :])
        return ks[np.any(gap * r0 <= 2.0 * self.tol, axis=1)]

    def _on_surface_bvh(self, points: np.ndarray) -> bool:
        if self._scene is None:
            import open3d as o3d

            self._scene = o3d.t.geometry.RaycastingScene()
            self._scene.add_triangles(
                o3d.core.Tensor(self.vertices.astype(np.float32)), o3d.core.Tensor(self.faces.astype(np.uint32))
            )
        import open3d as o3d

        d = self._scene.compute_distance(o3d.core.Tensor(np.asarray(points, dtype=np.float32))).numpy()
        return bool(np.all(d <= self.tol))

    def order(self, axis: np.ndarray) -> int:
        """Symmetry order ``m >= 1`` about ``axis`` (part frame) through the centre."""
        axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
        if not self.corners:
            # the vertex-based prefilters assume exact symmetry of the tessellation (see ``corners``)
            ks = np.arange(self.max_order, 1, -1)
            rots = axis_rotations(axis, 2.0 * np.pi / ks)
            return next((int(k) for k, R in zip(ks, rots, strict=True) if self.maps(R)), 1)
        ks = self.candidate_orders(axis)
        if len(ks) == 0:
            return 1
        rots = axis_rotations(axis, 2.0 * np.pi / ks)
        # Small meshes: the mesh's own vertices are as cheap to test as the hull's.
        alive = np.arange(len(ks)) if len(self.vertices) <= _SMALL else np.flatnonzero(self._hull_maps(rots))
        for i in alive:
            if self.maps(rots[i]):
                return int(ks[i])
        return 1


def symmetry_yaws(order: int) -> list[float]:
    """The equivalent yaws ``2 pi j / m`` (radians) of an ``m``-fold symmetry, ``j = 0..m-1``."""
    return [2.0 * np.pi * j / order for j in range(order)]
