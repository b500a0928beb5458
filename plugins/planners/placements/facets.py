"""Convex hull of a part and its support facets (clusters of coplanar hull faces).

A part resting on a table touches it with a face of its convex hull. Hull
triangles that lie in one plane (a box face is two triangles; a noisy scan has
many nearly coplanar ones) form one *support facet*. Clustering uses the
angle between face normals: adjacent faces whose normals differ by less than
``angle_tol`` are joined, and a cluster whose normals spread more than
``angle_tol`` from their mean (a finely tessellated curve chaining up) is
split again by region growing from its largest face.

Everything is in the part frame, metres. Normals point out of the hull.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from asmteach.core.errors import UserError

__all__ = ["SupportFacets", "convex_hull", "support_facets"]


@dataclass
class SupportFacets:
    """Support facets of a convex hull.

    Attributes
    ----------
    hull : the convex hull (watertight, outward normals), part frame, metres.
    face_cluster : ``(F,) int`` facet index of each hull face.
    normals : ``(C, 3) float`` outward unit normal of each facet (area-weighted mean).
    offsets : ``(C,) float`` support-plane offset ``max(v . n)`` over the facet's vertices, metres.
    areas : ``(C,) float`` facet area, m^2.
    edges : ``(E, 2) int`` hull vertex ids of the facets' boundary edges, oriented counter-clockwise
        seen from outside (the facet interior is on the left of ``a -> b`` about ``n``).
    edge_cluster : ``(E,) int`` facet owning each boundary edge.
    edge_neighbor : ``(E,) int`` facet on the other side of the edge (where the part topples to).
    vertices, faces, face_normals, face_areas, face_centers : plain-array copies of the hull's
        (trimesh's tracked arrays re-hash on every operation, which dominates small meshes).
    """

    hull: trimesh.Trimesh
    face_cluster: np.ndarray
    normals: np.ndarray
    offsets: np.ndarray
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


def convex_hull(mesh: trimesh.Trimesh, *, name: str = "the mesh") -> trimesh.Trimesh:
    """Convex hull of ``mesh``; :class:`UserError` when the mesh is flat or degenerate.

    The hull of a flat mesh (a plane, a sheet) has no volume and no facet a
    part could rest on, so it is refused with the thickness measured.
    """
    vertices = np.asarray(mesh.vertices, dtype=float).view(np.ndarray)
    if len(vertices) < 4:
        raise UserError(f"{name} has {len(vertices)} vertices; a solid needs at least 4")
    extent = float(np.ptp(vertices, axis=0).max())
    # The thinnest extent over principal directions: SVD of centred vertices.
    centred = vertices - vertices.mean(axis=0)
    vt = np.linalg.svd(centred, full_matrices=False)[2]
    thickness = float(np.ptp(centred @ vt[-1]))
    if extent <= 0.0 or thickness < 1e-6 * max(extent, 1e-12):
        raise UserError(
            f"{name} is flat or degenerate (thickness {thickness * 1000:.4f} mm over {extent * 1000:.3f} mm); "
            "a part resting on a table needs a closed solid"
        )
    try:
        hull = mesh.convex_hull
    except Exception as exc:  # noqa: BLE001 - qhull raises its own error types
        raise UserError(
            f"{name}: its convex hull cannot be computed ({type(exc).__name__}); is it degenerate?"
        ) from None
    if len(hull.faces) < 4 or not hull.is_watertight or hull.volume <= 0.0:
        raise UserError(f"{name}: its convex hull is degenerate (volume {hull.volume:.3g} m^3); check the mesh")
    return hull


def _directed_edge_neighbors(hull: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Directed edges (face winding), their face and the face across each edge."""
    edges = hull.edges.view(np.ndarray)  # (3F, 2), edge k belongs to face k // 3, in winding order
    edge_face = hull.edges_face.view(np.ndarray)
    pairs = trimesh.grouping.group_rows(hull.edges_sorted.view(np.ndarray), require_count=2)
    if len(pairs) * 2 != len(edges):
        raise UserError("the convex hull is not a closed 2-manifold; the mesh is degenerate")
    pairs = np.asarray(pairs)
    neighbor = np.empty(len(edges), dtype=np.int64)
    neighbor[pairs[:, 0]] = edge_face[pairs[:, 1]]
    neighbor[pairs[:, 1]] = edge_face[pairs[:, 0]]
    return edges, edge_face, neighbor


def _cluster_faces(hull: trimesh.Trimesh, normals: np.ndarray, areas: np.ndarray, angle_tol: float) -> np.ndarray:
    """Facet label of each hull face (see the module docstring)."""
    n_faces = len(normals)
    adj = hull.face_adjacency.view(np.ndarray)
    close = hull.face_adjacency_angles.view(np.ndarray) < angle_tol
    graph = coo_matrix((np.ones(int(close.sum())), (adj[close, 0], adj[close, 1])), shape=(n_faces, n_faces))
    n_comp, labels = connected_components(graph, directed=False)
    # A component must stay within angle_tol of its mean normal; else split it by region growing.
    mean = np.zeros((n_comp, 3))
    np.add.at(mean, labels, normals * areas[:, None])
    mean /= np.linalg.norm(mean, axis=1, keepdims=True)
    spread = np.arccos(np.clip(np.einsum("ij,ij->i", normals, mean[labels]), -1.0, 1.0))
    bad = np.unique(labels[spread > angle_tol])
    if len(bad) == 0:
        return labels
    neighbors: list[list[int]] = [[] for _ in range(n_faces)]
    for a, b in adj[close]:
        neighbors[a].append(int(b))
        neighbors[b].append(int(a))
    cos_tol = np.cos(angle_tol)
    next_label = n_comp
    for comp in bad:
        members = np.flatnonzero(labels == comp)
        unassigned = set(members.tolist())
        for seed in members[np.argsort(-areas[members], kind="stable")]:
            if seed not in unassigned:
                continue
            seed_n = normals[seed]
            stack = [int(seed)]
            unassigned.discard(int(seed))
            while stack:
                f = stack.pop()
                labels[f] = next_label
                for g in neighbors[f]:
                    if g in unassigned and normals[g] @ seed_n >= cos_tol:
                        unassigned.discard(g)
                        stack.append(g)
            next_label += 1
    _, labels = np.unique(labels, return_inverse=True)
    return labels


def support_facets(hull: trimesh.Trimesh, *, angle_tol: float = np.radians(1.0)) -> SupportFacets:
    """Cluster the faces of a convex ``hull`` into support facets.

    Parameters
    ----------
    hull : convex hull in the part frame (metres), e.g. from :func:`convex_hull`.
    angle_tol : radians; faces within this angle of each other (and of the
        facet's mean normal) are one facet.
    """
    vertices = np.array(hull.vertices, dtype=float)
    faces = np.array(hull.faces, dtype=np.int64)
    face_normals = np.array(hull.face_normals, dtype=float)
    triangles = vertices[faces]
    cross = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    areas_f = 0.5 * np.linalg.norm(cross, axis=1)
    labels = _cluster_faces(hull, face_normals, areas_f, angle_tol)
    n_clusters = int(labels.max()) + 1
    normals = np.zeros((n_clusters, 3))
    np.add.at(normals, labels, face_normals * areas_f[:, None])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    areas = np.bincount(labels, weights=areas_f, minlength=n_clusters)

    # Support plane offset: the farthest facet vertex along the facet normal.
    proj = np.einsum("fkj,fj->fk", triangles, normals[labels])
    offsets = np.full(n_clusters, -np.inf)
    np.maximum.at(offsets, labels, proj.max(axis=1))

    edges, edge_face, neighbor_face = _directed_edge_neighbors(hull)
    owner = labels[edge_face]
    across = labels[neighbor_face]
    boundary = owner != across
    return SupportFacets(
        hull=hull,
        face_cluster=labels,
        normals=normals,
        offsets=offsets,
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
