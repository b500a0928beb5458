"""Validation of a part mesh before grasp planning: one clear message per problem.

Each check raises :class:`~asmteach.core.errors.UserError` naming the part, the
cause and the fix: millimetres given as metres, open surfaces (thin shells
without an inside), inconsistent or inward normals, no surface area, walls too
thin for flat pads, parts too small to grip and parts wider than the stroke
everywhere (naming the part's smallest width against the stroke).
"""

from __future__ import annotations

import numpy as np
import trimesh

from asmteach.core.errors import UserError
from asmteach.core.models import HandSpec
from asmteach.core.parts import MAX_EXTENT_M

__all__ = ["check_graspable_width", "check_mesh", "check_too_small", "check_wall_thickness", "min_width"]


def check_mesh(mesh: trimesh.Trimesh, name: str) -> None:
    """Refuse meshes that ray casting through the part cannot handle (part frame, metres)."""
    v = np.asarray(mesh.vertices, dtype=float)
    if len(mesh.faces) == 0 or not np.all(np.isfinite(v)):
        raise UserError(f"part {name!r}: the mesh has no triangles or non-finite vertices; export it again")
    ext = float(np.max(mesh.extents))
    if ext > MAX_EXTENT_M:
        raise UserError(
            f"part {name!r}: the mesh is {ext:.0f} units across; it looks like millimetres. "
            "Scale it to metres (--units mm, or mesh_units: mm in the part YAML)"
        )
    if float(mesh.area) <= 0.0:
        raise UserError(f"part {name!r}: the mesh has zero surface area (degenerate triangles only)")
    if not mesh.is_watertight:
        open_edges = len(trimesh.grouping.group_rows(mesh.edges_sorted, require_count=1))
        raise UserError(
            f"part {name!r}: the mesh is an open shell ({open_edges} open edges), so it has no inside to grasp "
            "across; close it (e.g. trimesh.repair.fill_holes) or model the part as a solid"
        )
    if not mesh.is_winding_consistent:
        raise UserError(
            f"part {name!r}: face normals are degenerate (winding flips between neighbouring faces); "
            "repair them (trimesh.repair.fix_normals or MeshLab 'Re-Orient all faces coherently')"
        )
    if float(mesh.volume) <= 0.0:
        raise UserError(
            f"part {name!r}: face normals point inward (volume {mesh.volume:.3g} m^3 <= 0); "
            "flip them (trimesh.repair.fix_inversion) and export again"
        )


def check_wall_thickness(widths: np.ndarray, name: str, min_thickness: float) -> None:
    """Refuse thin shells: most through-part distances below ``min_thickness`` metres.

    ``widths`` are the distances through the part from each surface sample
    along its inward normal (``inf`` where no exit was found).
    """
    finite = widths[np.isfinite(widths)]
    if len(finite) < max(3, int(0.5 * len(widths))):
        raise UserError(
            f"part {name!r}: rays through the part along the inward normals found no opposite surface for "
            f"{len(widths) - len(finite)} of {len(widths)} samples; the normals are degenerate or the mesh "
            "self-intersects; repair the mesh"
        )
    typical = float(np.percentile(finite, 90))
    if typical < min_thickness:
        raise UserError(
            f"part {name!r}: a thin shell (90% of its walls are under {typical * 1000:.2f} mm thick, "
            f"limit {min_thickness * 1000:.1f} mm); flat pads cannot hold it; model it as a solid"
        )


def min_width(mesh: trimesh.Trimesh) -> float:
    """The part's smallest width (metres): the least distance between two parallel planes enclosing it.

    Taken over the normals of its convex hull's faces (the exact minimum for a convex polytope is attained
    at a face normal or an edge-edge direction; over face normals it is within a hair of it for tessellated
    solids, and never below it).
    """
    hull = mesh.convex_hull
    v = np.asarray(hull.vertices, dtype=float)
    n = np.asarray(hull.face_normals, dtype=float)
    proj = v @ n.T  # (v, f)
    return float(np.min(proj.max(axis=0) - proj.min(axis=0)))


def check_too_small(widths: np.ndarray, name: str, hand: HandSpec, min_thickness: float) -> None:
    """Refuse a part narrower everywhere than the hand can grip: every through-part distance under
    ``max(hand.min_width, min_thickness)`` metres."""
    finite = widths[np.isfinite(widths)]
    limit = max(float(hand.min_width), float(min_thickness))
    if len(finite) and float(np.max(finite)) < limit:
        raise UserError(
            f"part {name!r}: too small: at most {float(np.max(finite)) * 1000:.2f} mm across at every sampled "
            f"contact pair, under the {limit * 1000:.2f} mm the hand {hand.name!r} grips (closing limit "
            f"{hand.min_width * 1000:.1f} mm, thinnest wall {min_thickness * 1000:.1f} mm); check the units or use "
            "a finer gripper"
        )


def check_graspable_width(
    widths: np.ndarray, name: str, hand: HandSpec, max_opening: float, *, mesh: trimesh.Trimesh | None = None
) -> None:
    """Refuse a part with no pair of opposite faces between ``hand.min_width`` and ``max_opening`` metres.

    With ``mesh``, the message gives the part's smallest width (:func:`min_width`) against the stroke.
    """
    finite = widths[np.isfinite(widths)]
    ok = (finite >= hand.min_width) & (finite <= max_opening)
    if not np.any(ok):
        narrowest = float(np.min(finite)) if len(finite) else float("inf")
        smallest = min_width(mesh) if mesh is not None else narrowest
        stroke = float(hand.max_width)
        if smallest > max_opening:
            raise UserError(
                f"part {name!r}: too wide for the hand: its smallest width is {smallest * 1000:.1f} mm but the hand "
                f"{hand.name!r} opens {stroke * 1000:.1f} mm ({max_opening * 1000:.1f} mm with approach clearance); "
                "no graspable width: use a wider gripper"
            )
        raise UserError(
            f"part {name!r}: no graspable width: its smallest width is {smallest * 1000:.1f} mm, under the hand "
            f"{hand.name!r}'s {stroke * 1000:.1f} mm stroke ({max_opening * 1000:.1f} mm with approach "
            f"clearance), but only across edges or corners; every pair of opposite faces is at least "
            f"{narrowest * 1000:.1f} mm apart; use a wider gripper"
        )
