"""Validation of a part mesh before grasp planning: one clear message per problem.

Each check raises :class:`~asmteach.core.errors.UserError` naming the part, the
cause and the fix: millimetres given as metres, open surfaces (thin shells
without an inside), inconsistent or inward normals, no surface area, walls too
thin for flat pads, and parts wider than the stroke everywhere.
"""

from __future__ import annotations

import numpy as np
import trimesh

from asmteach.core.errors import UserError
from asmteach.core.models import HandSpec
from asmteach.core.parts import MAX_EXTENT_M

__all__ = ["check_graspable_width", "check_mesh", "check_wall_thickness"]


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


def check_graspable_width(widths: np.ndarray, name: str, hand: HandSpec, max_opening: float) -> None:
    """Refuse a part with no pair of opposite faces between ``hand.min_width`` and ``max_opening`` metres."""
    finite = widths[np.isfinite(widths)]
    ok = (finite >= hand.min_width) & (finite <= max_opening)
    if not np.any(ok):
        narrowest = float(np.min(finite)) if len(finite) else float("inf")
        raise UserError(
            f"part {name!r}: no graspable width: the part is at least {narrowest * 1000:.1f} mm across at "
            f"every sampled contact pair, but the hand {hand.name!r} opens to {max_opening * 1000:.1f} mm "
            f"(stroke {hand.max_width * 1000:.1f} mm less approach clearance); use a wider gripper"
        )
