"""Refine the pieces that protrude: clip each one to the mesh, cut it in two, hull the halves again.

A convex piece protrudes where it bridges a concavity of the mesh: a hull
replaced a sliver the plane split could not cut (a hole wall's two facets),
or CoACD accepted a piece whose concavity was within its normalised
threshold. Such a piece ``P`` is replaced by the hulls of the bodies of
``(P and mesh)`` on each side of a plane through the bottom of the
concavity (the mesh point nearest to the farthest protruding point), the
plane's normal being the principal axis of ``P`` whose cut protrudes least.
The halves' union still holds ``P and mesh``, so coverage is kept exactly,
and their protrusion is never larger than ``P``'s. The worst piece is
refined first until every piece is within the tolerance or the piece count
reaches its bound.

Protrusions are judged here on each piece's vertices, face centres and a
few surface samples; the result is measured afterwards by
:func:`asmteach.core.convex_pieces.measure.fidelity`.

Units: metres, part frame.
"""

from __future__ import annotations

import heapq

import manifold3d
import numpy as np
import trimesh

from asmteach.core.convex_pieces.measure import triangle_distance
from asmteach.core.convex_pieces.meshes import to_manifold
from asmteach.core.convex_pieces.pieces import hull_corners, piece_hull

_PIECE_SAMPLES = 64
"""Surface samples per piece (besides its vertices and face centres) when judging its protrusion."""


_BARY = np.array([(i, j, 6 - i - j) for i in range(7) for j in range(7 - i)], dtype=float) / 6.0
"""Barycentric grid (28 points, edges and corners included) laid on each face of a piece: a face bridging
a concavity is farthest from the mesh inside it, not at a vertex."""


_MAX_CUTS = 10
"""Cutting planes tried per refined piece."""


class _MeshQuery:
    """Distance outside a closed mesh, 0 inside (Open3D ray casting and nearest triangle, float64 distance; m)."""

    def __init__(self, mesh: trimesh.Trimesh) -> None:
        import open3d as o3d

        self._o3d = o3d
        self.triangles = np.asarray(mesh.triangles, dtype=float)
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(
            o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
            o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)),
        )

    def outside(self, pts: np.ndarray) -> np.ndarray:
        t = self._o3d.core.Tensor(np.asarray(pts, dtype=np.float32))
        out = self.scene.compute_occupancy(t).numpy() < 0.5
        dist = np.zeros(len(pts))
        if out.any():
            # the nearest triangle from Open3D, the distance to it in float64 (as the measure does)
            p = np.asarray(pts, dtype=float)[out]
            ans = self.scene.compute_closest_points(self._o3d.core.Tensor(p.astype(np.float32)))
            face = ans["primitive_ids"].numpy().astype(np.int64)
            tri = self.triangles[face]
            dist[out] = triangle_distance(p, tri[:, 0], tri[:, 1], tri[:, 2])
        return dist

    def closest(self, p: np.ndarray) -> tuple[np.ndarray, int]:
        """The mesh point nearest to ``p`` and its triangle's index."""
        t = self._o3d.core.Tensor(np.asarray(p, dtype=np.float32).reshape(1, 3))
        ans = self.scene.compute_closest_points(t)
        return ans["points"].numpy()[0].astype(float), int(ans["primitive_ids"].numpy()[0])


def _protrusion(q: _MeshQuery, verts: np.ndarray, rng: np.random.Generator) -> tuple[float, np.ndarray]:
    """Largest distance outside the mesh of the piece's vertices, face centres and surface samples, and where."""
    h = piece_hull(verts)
    grid = np.einsum("kj,fjc->fkc", _BARY, h.triangles).reshape(-1, 3)
    pts = np.vstack([verts, grid, trimesh.sample.sample_surface(h, _PIECE_SAMPLES, seed=rng)[0]])
    d = q.outside(pts)
    i = int(np.argmax(d))
    return float(d[i]), pts[i]


def _bodies(man: manifold3d.Manifold, min_volume: float) -> list[tuple[np.ndarray, manifold3d.Manifold]]:
    """Hull corners of each body of ``man`` larger than ``min_volume`` (m^3), with the body."""
    out = []
    for body in man.decompose():
        if body.volume() <= min_volume:
            continue
        v = hull_corners(np.asarray(body.to_mesh().vert_properties)[:, :3].astype(float))
        if v is not None:
            out.append((v, body))
    return out


def _holds(verts: np.ndarray, p: np.ndarray) -> bool:
    """Whether the convex hull of ``verts`` holds the point ``p`` (to a nanometre)."""
    h = piece_hull(verts)
    return bool(np.all(h.face_normals @ p - np.einsum("ij,ij->i", h.face_normals, h.triangles[:, 0]) <= 1e-9))


def _cut_normals(mesh: trimesh.Trimesh, verts: np.ndarray, face: int) -> np.ndarray:
    """Normals of the planes tried through a concavity's bottom: the planes of the faces around it (a cut
    along a face parts the material on its two sides, as the plane split does), the bisectors of the
    nearest face with its neighbours (a crease), and the piece's principal axes."""
    around = np.unique(np.concatenate([mesh.vertex_faces[k] for k in mesh.faces[face]]))
    around = around[around >= 0]
    normals = mesh.face_normals
    cands = [normals[face], *normals[around], *(normals[face] - normals[around])]
    cands += list(np.linalg.svd(verts - verts.mean(axis=0), full_matrices=False)[2])
    cands = np.asarray(cands, dtype=float)
    norm = np.linalg.norm(cands, axis=1)
    cands = cands[norm > 1e-3] / norm[norm > 1e-3, None]
    # one normal per plane (n and -n are one), in the order above, at most _MAX_CUTS of them (each is a trial cut)
    cands *= np.where(cands[np.arange(len(cands)), np.argmax(np.abs(cands), axis=1)] < 0, -1.0, 1.0)[:, None]
    _, first = np.unique(np.round(cands, 3), axis=0, return_index=True)
    return cands[np.sort(first)][:_MAX_CUTS]


def refine_protruding(
    pieces: list[np.ndarray], mesh: trimesh.Trimesh, tolerance: float, max_pieces: int, seed: int = 0
) -> list[np.ndarray]:
    """``pieces`` with every piece protruding more than ``tolerance`` metres refined (see the module docstring).

    At most ``max_pieces`` pieces result; a piece no cut improves is kept as
    it is. Deterministic for a given ``seed`` (the surface samples).
    """
    rng = np.random.default_rng(seed)
    q = _MeshQuery(mesh)
    solid = to_manifold(mesh)
    min_volume = 1e-9 * float(mesh.volume)
    # each entry: vertices, the clipped body it came from (None: not clipped yet), protrusion and where
    items: list[tuple[np.ndarray, manifold3d.Manifold | None]] = []
    heap: list[tuple[float, int, np.ndarray]] = []
    for v in pieces:
        p, at = _protrusion(q, v, rng)
        items.append((v, None))
        if p > tolerance:
            heapq.heappush(heap, (-p, len(items) - 1, at))
    alive = [True] * len(items)
    count = len(items)
    while heap and count < max_pieces:
        neg, i, at = heapq.heappop(heap)
        v, body = items[i]
        if body is None:
            body = manifold3d.Manifold.hull_points(v) ^ solid
        origin, face = q.closest(at)
        best: tuple[float, list[tuple[np.ndarray, manifold3d.Manifold, float, np.ndarray]]] | None = None
        for n in _cut_normals(mesh, v, face):
            halves = []
            for side in body.split_by_plane(n.tolist(), float(n @ origin)):
                halves += _bodies(side, min_volume)
            if len(halves) < 2:
                continue
            judged = [(hv, hb, *_protrusion(q, hv, rng)) for hv, hb in halves]
            worst = max(j[2] for j in judged)
            if best is None or worst < best[0]:
                best = (worst, judged)
        # A cut helps when the halves protrude less, or as much but no longer over this concavity (the piece
        # bridged two: the next cut takes the other one).
        if best is None or count + len(best[1]) - 1 > max_pieces:
            continue
        worse = best[0] > -neg + 1e-7
        if worse or (best[0] >= -neg - 1e-7 and any(_holds(hv, at) for hv, *_ in best[1])):
            continue  # no cut through the concavity helps: the piece stays as it is
        alive[i] = False
        count += len(best[1]) - 1
        for hv, hb, p, where in best[1]:
            items.append((hv, hb))
            alive.append(True)
            if p > tolerance:
                heapq.heappush(heap, (-p, len(items) - 1, where))
    return [v for (v, _), keep in zip(items, alive, strict=True) if keep]
