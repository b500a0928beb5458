"""Repair of the small defects CAD exports and scans carry: open edges, flipped faces, inverted shells.

A part's mass, stable placements, grasps and collision pieces all need a
closed, consistently wound surface. :func:`repair_mesh` fixes what can be
fixed without guessing at the shape, in order:

1. vertices merged (STL stores each triangle's corners separately),
   degenerate and duplicate faces dropped;
2. holes (loops of open edges) filled by trimesh's hole filler, and, when it
   cannot close them all, by MeshFix (``pymeshfix``), whose repair is kept
   only when the surface it adds is at most ``max_fill_area`` of the part's
   surface (a few missing triangles, not a missing side whose shape would
   have to be guessed). Where both close the holes, the fill that adds the
   least surface is kept: trimesh closes a four-edge loop by either diagonal,
   and two missing triangles that met across a fold (a hole's wall and the
   bottom face) came back as two faces cutting 470 mm^2 across the inside;
   the missing faces are the smallest surface that closes the loop;
3. faces re-wound to agree with their neighbours and the shell turned
   outward (positive volume).

Each change is returned as a line a user can read. A mesh that stays open is
refused with :class:`~asmteach.core.errors.UserError` naming how many holes
remain and where the largest one is (its centre in the mesh's own units).
Units: whatever the mesh is in; nothing here scales it.
"""

from __future__ import annotations

import numpy as np
import trimesh

from asmteach.core.errors import UserError

__all__ = ["holes", "repair_mesh"]


def holes(mesh: trimesh.Trimesh) -> list[np.ndarray]:
    """Vertex ids of each loop of open edges (edges used by one face only), largest loop first."""
    edges = np.sort(mesh.edges, axis=1)
    open_rows = trimesh.grouping.group_rows(edges, require_count=1)
    if len(open_rows) == 0:
        return []
    open_edges = edges[np.asarray(open_rows).ravel()]
    loops = trimesh.graph.connected_components(open_edges, min_len=1)
    return sorted((np.asarray(c) for c in loops), key=len, reverse=True)


def _closed(mesh: trimesh.Trimesh) -> bool:
    return bool(mesh.is_watertight)


def _pymeshfix(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    import pymeshfix

    fix = pymeshfix.MeshFix(np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64))
    fix.repair()
    return trimesh.Trimesh(np.asarray(fix.points), np.asarray(fix.faces), process=True)


def repair_mesh(
    mesh: trimesh.Trimesh, *, name: str = "the mesh", max_fill_area: float = 0.02
) -> tuple[trimesh.Trimesh, list[str]]:
    """A closed, outward-wound copy of ``mesh`` and the changes made, one line each.

    ``name`` is used in messages (a file name). Raises :class:`UserError`
    when the holes cannot be closed.
    """
    notes: list[str] = []
    m = trimesh.Trimesh(np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces), process=True)
    m.merge_vertices()
    n_faces = len(m.faces)
    m.update_faces(m.nondegenerate_faces())
    m.update_faces(m.unique_faces())
    m.remove_unreferenced_vertices()
    if len(m.faces) < n_faces:
        notes.append(f"dropped {n_faces - len(m.faces)} degenerate or duplicate faces")
    if len(m.faces) < 4:
        raise UserError(f"{name}: only {len(m.faces)} usable triangles; it is not a solid part")

    found = holes(m)
    if found:
        n_edges = sum(len(h) for h in found)
        filled = m.copy()
        trimesh.repair.fill_holes(filled)
        how = "trimesh"
        if not _closed(filled):
            filled, how = _pymeshfix(m), "MeshFix"
        else:
            other = _pymeshfix(m)
            # MeshFix may also drop or move what it deems faulty: its fill competes only when it added faces alone
            if (
                _closed(other)
                and len(other.vertices) == len(m.vertices)
                and float(other.area) < float(filled.area) - 1e-9 * float(m.area)
            ):
                filled, how = other, "MeshFix (less added surface than trimesh's fill)"
        added = (float(filled.area) - float(m.area)) / max(float(filled.area), 1e-30)
        # trimesh fills only triangle and quad loops: a missing triangle comes back exactly, whatever its size
        if how == "MeshFix" and _closed(filled) and added > max_fill_area:
            centre = np.asarray(m.vertices)[found[0]].mean(axis=0)
            raise UserError(
                f"{name}: its holes cover {100 * added:.0f}% of the surface, too much to fill without guessing "
                f"the shape; the largest ({len(found[0])} open edges) is around "
                f"({centre[0]:.4g}, {centre[1]:.4g}, {centre[2]:.4g}) in the file's units. Export it closed"
            )
        if not _closed(filled):
            left = holes(filled) or found
            centre = np.asarray(filled.vertices if holes(filled) else m.vertices)[left[0]].mean(axis=0)
            raise UserError(
                f"{name}: {len(left)} hole(s) could not be closed; the largest ({len(left[0])} open edges) is "
                f"around ({centre[0]:.4g}, {centre[1]:.4g}, {centre[2]:.4g}) in the file's units. "
                "Close it in the CAD tool and export again"
            )
        notes.append(
            f"filled {len(found)} hole(s) ({n_edges} open edges) with {how}; "
            f"{len(filled.faces) - len(m.faces):+d} faces"
        )
        m = filled

    before = np.asarray(m.faces).copy()
    trimesh.repair.fix_winding(m)
    rewound = int(np.count_nonzero(np.any(np.asarray(m.faces) != before, axis=1)))
    if rewound:
        notes.append(f"re-wound {rewound} faces to agree with their neighbours")
    if float(m.volume) < 0:
        m.invert()
        notes.append("turned the shell outward (its normals pointed inward)")
    return m, notes
