"""Convex pieces of a part for a physics engine (dynamic bodies need convex shapes).

Three routes, the first that applies:

1. a parametric solid with no ``subtract``: its primitives (boxes, cylinders)
   are convex and their union is the part, exactly;
2. otherwise the mesh is split recursively with manifold3d along the plane of
   its largest face that cuts it, until every piece is convex (at most
   ``max_pieces``; a piece left over is replaced by its convex hull);
3. if the pieces' volume strays from the part's by more than 2 %, PyBullet's
   V-HACD is tried too and the closer of the two kept.

Known limit: manifold3d sometimes leaves a zero-thickness sheet where a cut
runs through coplanar faces; the piece holding it is then replaced by its
hull, which fills that concavity (:func:`pieces_volume_error` reports it).

Part frame, metres.
"""

from __future__ import annotations

import logging
import tempfile
from pathlib import Path

import manifold3d
import numpy as np
import trimesh

from asmteach.core.cstdout import silenced_c_stdout
from asmteach.core.interfaces import PartModel
from asmteach.core.models import Primitive

__all__ = ["convex_pieces", "pieces_volume_error", "split_convex"]

log = logging.getLogger(__name__)


def _primitive(p: Primitive) -> trimesh.Trimesh:
    """The same tessellation as the part library's (64-sided cylinders)."""
    if p.shape == "box":
        m = trimesh.creation.box(extents=p.size)
    else:
        m = trimesh.creation.cylinder(radius=p.radius, height=p.height, sections=64)
    m.apply_transform(p.pose)
    return m


def _to_manifold(mesh: trimesh.Trimesh) -> manifold3d.Manifold:
    return manifold3d.Manifold(
        manifold3d.Mesh(
            vert_properties=np.asarray(mesh.vertices, dtype=np.float32),
            tri_verts=np.asarray(mesh.faces, dtype=np.uint32),
        )
    )


def _to_trimesh(man: manifold3d.Manifold) -> trimesh.Trimesh:
    g = man.to_mesh()
    mesh = trimesh.Trimesh(np.asarray(g.vert_properties)[:, :3].astype(float), np.asarray(g.tri_verts), process=True)
    mesh.merge_vertices()
    # A cut through a plane that already holds faces can leave a zero-thickness sheet:
    # pairs of coincident back-to-back triangles. Remove both faces of every such pair.
    pairs = trimesh.grouping.group_rows(np.sort(mesh.faces, axis=1), require_count=2)
    if len(pairs):
        keep = np.ones(len(mesh.faces), dtype=bool)
        keep[np.asarray(pairs).ravel()] = False
        mesh.update_faces(keep)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.remove_unreferenced_vertices()
    return mesh


def _is_convex(mesh: trimesh.Trimesh, rel_tol: float = 1e-4) -> bool:
    hull = float(mesh.convex_hull.volume)
    return hull - float(mesh.volume) <= rel_tol * hull


def split_convex(mesh: trimesh.Trimesh, max_pieces: int = 64) -> tuple[list[trimesh.Trimesh], int]:
    """Pieces whose union is ``mesh``, and how many of them are hulls of non-convex leftovers."""
    # Coordinates are snapped to float32 first, as manifold3d stores them, so a cutting
    # plane through a face passes exactly through its vertices and leaves no sliver.
    start = trimesh.Trimesh(np.asarray(mesh.vertices, dtype=np.float32).astype(float), mesh.faces, process=True)
    todo, done, approx = [start], [], 0
    while todo:
        m = todo.pop()
        if _is_convex(m):
            done.append(m)
            continue
        if len(done) + len(todo) + 2 > max_pieces:
            done.append(m.convex_hull)
            approx += 1
            continue
        normals, offsets = m.face_normals, np.einsum("ij,ij->i", m.face_normals, m.triangles_center)
        signed = np.asarray(m.vertices) @ normals.T - offsets[None, :]
        cuts = (signed > 1e-7).any(axis=0) & (signed < -1e-7).any(axis=0)
        if not cuts.any():
            done.append(m.convex_hull)
            approx += 1
            continue
        # Faces on one plane share its area; cut along the plane with the most.
        key = np.round(np.c_[normals, offsets], 6)
        planes, inverse = np.unique(key, axis=0, return_inverse=True)
        inverse = inverse.ravel()
        area = np.bincount(inverse, weights=m.area_faces, minlength=len(planes))
        usable = np.zeros(len(planes), dtype=bool)
        usable[inverse[cuts]] = True
        best = int(np.argmax(np.where(usable, area, -1.0)))
        a, b = _to_manifold(m).split_by_plane(planes[best, :3].tolist(), float(planes[best, 3]))
        if min(a.volume(), b.volume()) < 1e-6 * float(m.volume):
            done.append(m.convex_hull)
            approx += 1
            continue
        todo += [_to_trimesh(a), _to_trimesh(b)]
    return done, approx


def _vhacd(mesh: trimesh.Trimesh) -> list[trimesh.Trimesh]:
    import pybullet

    with tempfile.TemporaryDirectory() as tmp:
        src, dst, logf = (str(Path(tmp) / n) for n in ("in.obj", "out.obj", "log.txt"))
        mesh.export(src)
        client = pybullet.connect(pybullet.DIRECT)
        try:
            with silenced_c_stdout():  # V-HACD prints progress on the C stdout
                pybullet.vhacd(src, dst, logf, resolution=400000, concavity=0.0002, physicsClientId=client)
        finally:
            pybullet.disconnect(client)
        scene = trimesh.load(dst, force="scene", split_object=True, group_material=False)
        return [g for g in scene.dump() if isinstance(g, trimesh.Trimesh)]


def convex_pieces(part: PartModel, max_pieces: int = 64) -> list[trimesh.Trimesh]:
    """Convex meshes whose union approximates ``part.mesh`` (see the module docstring)."""
    solid = part.spec.solid
    if solid is not None and not solid.subtract:
        return [_primitive(p) for p in solid.add]
    pieces, approx = split_convex(part.mesh, max_pieces)
    error = pieces_volume_error(part, pieces)
    if error <= 0.02:
        if approx:
            log.info("%s: %d of %d convex pieces are hulls (volume error %.2g)", part.name, approx, len(pieces), error)
        return pieces
    vhacd = _vhacd(part.mesh)
    v_error = pieces_volume_error(part, vhacd)
    best, best_error = (vhacd, v_error) if v_error < error else (pieces, error)
    log.warning("%s: convex pieces off by %.1f%% in volume (plane split %.1f%%, V-HACD %.1f%%)",
                part.name, 100 * best_error, 100 * error, 100 * v_error)  # fmt: skip
    return best


def pieces_volume_error(part: PartModel, pieces: list[trimesh.Trimesh]) -> float:
    """Relative volume difference between the pieces (overlaps counted twice) and the part."""
    return abs(sum(float(p.volume) for p in pieces) - float(part.mesh.volume)) / float(part.mesh.volume)
