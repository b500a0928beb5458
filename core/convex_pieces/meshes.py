"""Convex pieces of a mesh: the exact plane split along its own faces, and CoACD for curved free-form meshes."""

from __future__ import annotations

import manifold3d
import numpy as np
import trimesh

from asmteach.core.convex_pieces.pieces import DecompositionSettings, hull_corners

_MAX_TRIES = 12
"""Cutting planes tried on one piece before it is given up (replaced by its hull)."""

_CUT_OFFSET = 2e-7
"""Metres between a cutting plane and the face it is taken from (see :func:`split_convex`)."""


def to_manifold(mesh: trimesh.Trimesh) -> manifold3d.Manifold:
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


def split_convex(mesh: trimesh.Trimesh, max_pieces: int = 128) -> tuple[list[trimesh.Trimesh], int]:
    """Convex pieces whose union is ``mesh`` (cut along its own face planes), and how many are hulls.

    A piece is cut along the plane of its largest face that cuts it; a piece
    that no face plane splits any more (float32 slivers) or that would exceed
    ``max_pieces`` is replaced by its convex hull; the count of those is
    returned. Hulls of slivers are usually exact to a micrometre, which
    :func:`fidelity` measures.
    """
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
        # Faces on one plane share its area; cut along the plane with the most first. A plane whose cut
        # only shaves float noise off (its vertices beyond it are rounding) is skipped for the next one.
        key = np.round(np.c_[normals, offsets], 6)
        planes, inverse = np.unique(key, axis=0, return_inverse=True)
        inverse = inverse.ravel()
        area = np.bincount(inverse, weights=m.area_faces, minlength=len(planes))
        usable = np.zeros(len(planes), dtype=bool)
        usable[inverse[cuts]] = True
        man, split = to_manifold(m), None
        for best in np.argsort(-np.where(usable, area, -1.0))[: min(int(usable.sum()), _MAX_TRIES)]:
            # the plane's exact equation is its largest face's: the rounded key (1 um) only groups faces
            members = np.flatnonzero(inverse == best)
            f = int(members[np.argmax(m.area_faces[members])])
            # The cut runs 0.2 um off the face, on its open side: cut exactly through it, the face would stay
            # behind as a zero-thickness sheet joining the bodies beyond it (the two sides of a slot) into one
            # piece, whose hull then fills the slot. Off the face, the other side gains a 0.2 um slab at most.
            a, b = man.split_by_plane(normals[f].tolist(), float(offsets[f]) + _CUT_OFFSET)
            if min(a.volume(), b.volume()) >= 1e-6 * float(m.volume):
                split = (a, b)
                break
        if split is None:
            done.append(m.convex_hull)
            approx += 1
            continue
        for half in split:
            # A cut along a plane holding a face of the other side leaves a float-thin sheet there, a body of
            # its own: a further cut cannot part it from the rest, whose hull would then fill the gap. Drop
            # such sheets (under a micrometre thick on average); keep every real body as a piece of its own.
            for body in half.decompose():
                t = _to_trimesh(body)
                if len(t.faces) >= 4 and float(t.volume) > 1e-6 * float(t.area):
                    todo.append(t)
    return done, approx


def coacd_threshold(mesh: trimesh.Trimesh, settings: DecompositionSettings) -> float:
    """CoACD's concavity threshold for ``settings.tolerance`` metres on this mesh.

    CoACD measures concavity on the mesh scaled so its largest extent spans
    [-1, 1], so one normalised unit is half the largest extent.
    """
    half = 0.5 * float(np.max(mesh.extents))
    return float(np.clip(settings.tolerance / half, settings.min_coacd_threshold, 1.0))


def coacd_pieces(mesh: trimesh.Trimesh, settings: DecompositionSettings) -> list[np.ndarray]:
    """CoACD's convex pieces of a closed mesh (vertices ``(k, 3)``, same frame and units)."""
    import coacd

    coacd.set_log_level("error")
    # CoACD normalises internally; millimetres keep its absolute epsilons away from float noise.
    scale = 1000.0
    m = coacd.Mesh(np.asarray(mesh.vertices, dtype=float) * scale, np.asarray(mesh.faces, dtype=np.int32))
    # a part's mesh is closed and manifold already: the voxel remeshing of preprocessing would only blur it
    mode = "off" if mesh.is_watertight and mesh.is_winding_consistent else "on"
    parts = coacd.run_coacd(
        m,
        threshold=coacd_threshold(mesh, settings),
        preprocess_mode=mode,
        resolution=settings.coacd_resolution,
        seed=settings.seed,
        max_convex_hull=-1,
    )
    out = []
    for v, _ in parts:
        v = np.asarray(v, dtype=float) / scale
        if len(v) >= 4:
            out.append(hull_corners(v))
    return [v for v in out if v is not None]
