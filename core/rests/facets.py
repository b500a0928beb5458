"""Convex hull of a part and its support facets (clusters of coplanar hull faces).

A part resting on a table touches it with a face of its convex hull. Hull
triangles that lie in one plane (a box face is two triangles; a CAD export
rounded to float32 or a slightly uneven face gives many nearly coplanar ones,
with zero-area slivers among them) form one *support facet*. The merge rule
has two stated tolerances:

* angular: adjacent faces whose normals differ by less than ``angle_tol``
  (default 1 degree) are joined;
* distance: adjacent faces are joined when the vertices of one lie within
  ``merge_dist`` of the other's plane (default ``MERGE_DIST_REL = 1e-4`` of
  the hull's largest extent). This is what keeps a flat face whole when qhull
  leaves slivers on it: a sliver's normal can point anywhere, its vertices
  lie on the face.

A cluster must stay flat: a face neither within ``angle_tol`` of the
cluster's mean normal nor within ``merge_dist`` of its support plane (a
finely tessellated curve chaining up) makes the cluster split again by
region growing from its largest face, with the same two tests against that
face. A facet is then treated as flat: its support polygon is its boundary
projected on the plane of its (area-weighted) mean normal, and the part
rests on that plane (its vertices lie within the tolerances of it).

The hull comes straight from qhull (:class:`scipy.spatial.ConvexHull`): its
facet planes give exact outward normals (the triangles of one qhull facet
share its plane, so exactly coplanar faces cluster exactly) and its neighbour
table gives the face adjacency, so no mesh bookkeeping is needed; a
:class:`trimesh.Trimesh` view is built only when asked for.

Everything is in the part frame, metres. Normals point out of the hull.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import trimesh
from scipy.spatial import ConvexHull, QhullError

from asmteach.core.errors import UserError
from asmteach.core.geometry import cross  # re-exported: the placements modules take it from here

__all__ = ["MERGE_DIST_REL", "Hull", "SupportFacets", "convex_hull", "cross", "is_closed", "support_facets"]

# Default distance tolerance of the facet merge, as a fraction of the hull's largest extent: faces whose
# vertices lie within it of a facet's plane are that facet (0.02 mm on a 200 mm part: far below what a
# table or a gripper can tell apart, far above the float32 rounding of an STL).
MERGE_DIST_REL = 1e-4


@dataclass
class Hull:
    """A convex hull as plain arrays (part frame, metres).

    Attributes
    ----------
    vertices : ``(V, 3) float`` hull vertices.
    faces : ``(F, 3) int`` triangles, counter-clockwise seen from outside.
    normals : ``(F, 3) float`` outward unit normal of each face (its qhull facet plane).
    areas : ``(F,) float`` face areas, m^2 (0 for the slivers qhull's triangulation may leave).
    neighbors : ``(F, 3) int`` face across the directed edge ``faces[:, k] -> faces[:, (k + 1) % 3]``.
    volume : m^3.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    areas: np.ndarray
    neighbors: np.ndarray
    volume: float

    @cached_property
    def mesh(self) -> trimesh.Trimesh:
        """The hull as a watertight :class:`trimesh.Trimesh` (built on first use)."""
        return trimesh.Trimesh(self.vertices, self.faces, face_normals=self.normals, process=False)

    @cached_property
    def center_mass(self) -> np.ndarray:
        """``(3,)`` centroid of the solid hull (uniform density), metres."""
        tri = self.vertices[self.faces]
        origin = self.vertices.mean(axis=0)
        # Tetrahedra from an interior point: signed volume and centroid of each.
        vol = np.einsum("ij,ij->i", tri[:, 0] - origin, cross(tri[:, 1] - origin, tri[:, 2] - origin)) / 6.0
        cen = (tri.sum(axis=1) + origin) / 4.0
        return (vol @ cen) / vol.sum()


def is_closed(faces: np.ndarray) -> bool:
    """True when every edge of the triangles ``faces`` (``(F, 3) int``) is shared by exactly two faces.

    The same test as :attr:`trimesh.Trimesh.is_watertight`, on plain arrays (no mesh caches to fill).
    """
    faces = np.asarray(faces, dtype=np.int64)
    if len(faces) == 0:
        return False
    e = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    key = e[:, 0] * (int(faces.max()) + 1) + e[:, 1]
    _, counts = np.unique(key, return_counts=True)
    return bool(np.all(counts == 2))


def _orient(
    simplices: np.ndarray, neighbors: np.ndarray, normals: np.ndarray, points: np.ndarray, scale: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Wind qhull's triangles counter-clockwise about their outward facet normal.

    Returns faces, face areas and the face across each directed edge. qhull's
    ``neighbors[f, i]`` is the face opposite vertex ``i``, so edge ``(0, 1)``
    borders ``neighbors[f, 2]`` and so on; flipping a face swaps two columns
    of both arrays. Zero-area slivers have no winding of their own: they take
    the one that agrees with their neighbours across their edges.
    """
    faces = simplices.astype(np.int64, copy=True)
    nb = neighbors.astype(np.int64, copy=True)
    tri = points[faces]
    c = cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    areas = 0.5 * np.linalg.norm(c, axis=1)
    flip = np.einsum("ij,ij->i", c, normals) < 0.0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    nb[flip] = nb[flip][:, [0, 2, 1]]
    edge_nb = nb[:, [2, 0, 1]]
    sliver = areas <= 1e-12 * scale * scale
    for _ in range(8 if sliver.any() else 0):
        # Directed edge a -> b of face f agrees with its neighbour g when g holds b -> a.
        a, b = faces, np.roll(faces, -1, axis=1)
        g = faces[edge_nb]  # (F, 3 edges, 3 vertices of g)
        g_next = np.roll(g, -1, axis=2)
        agree = np.any((g == b[:, :, None]) & (g_next == a[:, :, None]), axis=2)
        bad = sliver & ~np.all(agree, axis=1) & ~np.any(agree, axis=1)
        if not bad.any():
            break
        faces[bad] = faces[bad][:, [0, 2, 1]]
        nb[bad] = nb[bad][:, [0, 2, 1]]
        edge_nb = nb[:, [2, 0, 1]]
    return faces, areas, edge_nb


def convex_hull(mesh: trimesh.Trimesh | np.ndarray, *, name: str = "the mesh") -> Hull:
    """Convex hull of ``mesh`` (or of ``(n, 3)`` points); :class:`UserError` when flat or degenerate.

    The hull of a flat mesh (a plane, a sheet) has no volume and no facet a
    part could rest on, so it is refused with the thickness measured.
    """
    points = np.asarray(getattr(mesh, "vertices", mesh), dtype=float).view(np.ndarray)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 4:
        raise UserError(f"{name} has {len(points)} vertices; a solid needs at least 4")
    extent = float(np.ptp(points, axis=0).max())

    def flat(pts: np.ndarray) -> UserError:
        centred = pts - pts.mean(axis=0)
        thickness = float(np.ptp(centred @ np.linalg.svd(centred, full_matrices=False)[2][-1]))
        return UserError(
            f"{name} is flat or degenerate (thickness {thickness * 1000:.4f} mm over {extent * 1000:.3f} mm); "
            "a part resting on a table needs a closed solid"
        )

    if not np.isfinite(extent) or extent <= 0.0:
        raise flat(points)
    try:
        ch = ConvexHull(points)
    except QhullError:  # qhull refuses flat input ("initial simplex is flat")
        raise flat(points) from None
    verts = points[ch.vertices]
    # A convex body's width is at least 3 V / S (V = integral of the support distance over S / 3),
    # so only thin hulls need the exact thickness check.
    if ch.volume <= 0.0 or 3.0 * ch.volume / ch.area < 1e-6 * extent:
        centred = verts - verts.mean(axis=0)
        thickness = float(np.ptp(centred @ np.linalg.svd(centred, full_matrices=False)[2][-1]))
        if thickness < 1e-6 * extent or ch.volume <= 0.0:
            raise flat(points)
    remap = np.full(len(points), -1, dtype=np.int64)
    remap[ch.vertices] = np.arange(len(ch.vertices))
    normals = np.ascontiguousarray(ch.equations[:, :3])
    faces, areas, edge_nb = _orient(remap[ch.simplices], ch.neighbors, normals, verts, extent)
    return Hull(vertices=verts, faces=faces, normals=normals, areas=areas, neighbors=edge_nb, volume=float(ch.volume))


@dataclass
class SupportFacets:
    """Support facets of a convex hull.

    Attributes
    ----------
    hull : the convex hull (part frame, metres).
    face_cluster : ``(F,) int`` facet index of each hull face.
    normals : ``(C, 3) float`` outward unit normal of each facet (area-weighted mean).
    offsets : ``(C,) float`` support-plane offset ``max(v . n)`` over the facet's vertices, metres.
    depth : ``(C,) float`` how far the facet's lowest vertex lies below that plane, metres (0 when the
        facet is exactly planar; a scan's nearly coplanar faces give a positive depth).
    areas : ``(C,) float`` facet area, m^2.
    edges : ``(E, 2) int`` hull vertex ids of the facets' boundary edges, oriented counter-clockwise
        seen from outside (the facet interior is on the left of ``a -> b`` about ``n``).
    edge_cluster : ``(E,) int`` facet owning each boundary edge.
    edge_neighbor : ``(E,) int`` facet on the other side of the edge (where the part topples to).
    vertices, faces, face_normals, face_areas, face_centers : the hull's, per face.
    """

    hull: Hull
    face_cluster: np.ndarray
    normals: np.ndarray
    offsets: np.ndarray
    depth: np.ndarray
    areas: np.ndarray
    edges: np.ndarray
    edge_cluster: np.ndarray
    edge_neighbor: np.ndarray
    vertices: np.ndarray
    faces: np.ndarray
    face_normals: np.ndarray
    face_areas: np.ndarray
    face_centers: np.ndarray

    @property
    def count(self) -> int:
        """Number of facets."""
        return len(self.normals)

    def vertex_ids(self, c: int) -> np.ndarray:
        """Hull vertex ids of facet ``c`` (unique, sorted)."""
        return np.unique(self.faces[self.face_cluster == c])


def _components(n: int, a: np.ndarray, b: np.ndarray) -> tuple[int, np.ndarray]:
    """Connected components of the graph on ``n`` nodes with edges ``a[i] - b[i]``: count and labels.

    Union by hooking each edge's larger root onto its smaller one, then path
    compression by pointer jumping, until no edge joins two components; a few
    vectorised rounds, where a sparse-matrix graph search costs more to set up
    than a small hull takes to cluster.
    """
    root = np.arange(n)
    while len(a):
        ra, rb = root[a], root[b]
        cut = ra != rb
        if not cut.any():
            break
        a, b = a[cut], b[cut]
        # Pointers only go to smaller ids, so no cycle can form.
        np.minimum.at(root, np.maximum(ra[cut], rb[cut]), np.minimum(ra[cut], rb[cut]))
        while True:
            jumped = root[root]
            if np.array_equal(jumped, root):
                break
            root = jumped
    uniq, labels = np.unique(root, return_inverse=True)
    return len(uniq), labels


def _cluster_faces(hull: Hull, angle_tol: float, merge_dist: float) -> np.ndarray:
    """Facet label of each hull face (see the module docstring).

    Two adjacent faces are *close* when their normals differ by less than
    ``angle_tol`` or when the vertices of one lie within ``merge_dist`` of the
    other's plane (a sliver's normal means nothing, its vertices do). The
    connected components of close faces are the facets, unless a component
    strays from its own plane (a face neither within ``angle_tol`` of its
    mean normal nor within ``merge_dist`` of its support plane: a curve
    chaining up); such a component is split by region growing from its
    largest face with the same two tests against that face.
    """
    normals, areas = hull.normals, hull.areas
    n_faces = len(normals)
    tri = hull.vertices[hull.faces]
    plane_off = np.einsum("ij,ij->i", normals, tri[:, 0])
    # Each undirected edge once: from the face with the smaller index.
    f = np.repeat(np.arange(n_faces), 3)
    g = hull.neighbors.reshape(-1)
    once = f < g
    f, g = f[once], g[once]
    cos_tol = np.cos(angle_tol)
    g_off_f = np.abs(np.einsum("fkj,fj->fk", tri[g], normals[f]) - plane_off[f][:, None]).max(axis=1)
    f_off_g = np.abs(np.einsum("fkj,fj->fk", tri[f], normals[g]) - plane_off[g][:, None]).max(axis=1)
    close = (np.einsum("ij,ij->i", normals[f], normals[g]) > cos_tol) | (np.minimum(g_off_f, f_off_g) <= merge_dist)
    n_comp, labels = _components(n_faces, f[close], g[close])
    if n_comp == n_faces:
        return labels
    # A component must stay near its mean plane; else split it by region growing.
    mean = np.zeros((n_comp, 3))
    np.add.at(mean, labels, normals * areas[:, None])
    # A component of zero-area slivers only has no area-weighted mean: use its plain mean.
    empty = np.linalg.norm(mean, axis=1) <= 0.0
    if empty.any():
        np.add.at(mean, labels, np.where(empty[labels][:, None], normals, 0.0))
    mean /= np.linalg.norm(mean, axis=1, keepdims=True)
    proj = np.einsum("fkj,fj->fk", tri, mean[labels])
    top = np.full(n_comp, -np.inf)
    np.maximum.at(top, labels, proj.max(axis=1))
    off_plane = (top[labels] - proj.min(axis=1)) > merge_dist
    bad = np.unique(labels[(np.einsum("ij,ij->i", normals, mean[labels]) < cos_tol) & off_plane])
    if len(bad) == 0:
        return labels
    neighbors: list[list[int]] = [[] for _ in range(n_faces)]
    for a, b in zip(f[close].tolist(), g[close].tolist(), strict=True):
        neighbors[a].append(b)
        neighbors[b].append(a)
    next_label = n_comp
    for comp in bad:
        members = np.flatnonzero(labels == comp)
        unassigned = set(members.tolist())
        for seed in members[np.argsort(-areas[members], kind="stable")]:
            if seed not in unassigned:
                continue
            seed_n, seed_off = normals[seed], plane_off[seed]
            stack = [int(seed)]
            unassigned.discard(int(seed))
            while stack:
                face = stack.pop()
                labels[face] = next_label
                for other in neighbors[face]:
                    if other in unassigned and (
                        normals[other] @ seed_n >= cos_tol
                        or float(np.abs(tri[other] @ seed_n - seed_off).max()) <= merge_dist
                    ):
                        unassigned.discard(other)
                        stack.append(other)
            next_label += 1
    _, labels = np.unique(labels, return_inverse=True)
    return labels


def support_facets(hull: Hull, *, angle_tol: float = np.radians(1.0), merge_dist: float | None = None) -> SupportFacets:
    """Cluster the faces of a convex ``hull`` into support facets.

    Parameters
    ----------
    hull : convex hull in the part frame (metres), from :func:`convex_hull`.
    angle_tol : radians; faces within this angle of each other (and of the
        facet's seed or mean normal) are one facet.
    merge_dist : metres; a face whose vertices lie within this distance of an adjacent face's plane
        (and of the facet's plane) joins it whatever its normal. Default: ``MERGE_DIST_REL`` times the
        hull's largest extent.
    """
    vertices, faces, face_normals, areas_f = hull.vertices, hull.faces, hull.normals, hull.areas
    triangles = vertices[faces]
    if merge_dist is None:
        merge_dist = MERGE_DIST_REL * float(np.ptp(vertices, axis=0).max())
    labels = _cluster_faces(hull, angle_tol, merge_dist)
    n_clusters = int(labels.max()) + 1
    normals = np.zeros((n_clusters, 3))
    np.add.at(normals, labels, face_normals * areas_f[:, None])
    # A facet of slivers only (no area) keeps its faces' plain mean normal.
    empty = np.linalg.norm(normals, axis=1) <= 0.0
    if empty.any():
        np.add.at(normals, labels, np.where(empty[labels][:, None], face_normals, 0.0))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    areas = np.bincount(labels, weights=areas_f, minlength=n_clusters)

    # Support plane offset: the farthest facet vertex along the facet normal.
    proj = np.einsum("fkj,fj->fk", triangles, normals[labels])
    offsets = np.full(n_clusters, -np.inf)
    np.maximum.at(offsets, labels, proj.max(axis=1))
    lowest = np.full(n_clusters, np.inf)
    np.minimum.at(lowest, labels, proj.min(axis=1))

    # Directed edges in winding order; an edge between two facets bounds both.
    edges = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    owner = np.repeat(labels, 3)
    across = labels[hull.neighbors.reshape(-1)]
    boundary = owner != across
    return SupportFacets(
        hull=hull,
        face_cluster=labels,
        normals=normals,
        offsets=offsets,
        depth=offsets - lowest,
        areas=areas,
        edges=edges[boundary],
        edge_cluster=owner[boundary],
        edge_neighbor=across[boundary],
        vertices=vertices,
        faces=faces,
        face_normals=face_normals,
        face_areas=areas_f,
        face_centers=triangles.mean(axis=1),
    )
