"""The middle layer of the regrasp graph: stable placements as pose slots on the table.

A part is turned over by putting it down in another stable placement and
picking it up again. The slots are the most probable distinct placements at
sampled yaws where the part starts (:func:`placement_slots`), or, near the
edge of the robot's reach, the same slots moved toward the goal and clear of
the other obstacles (:func:`relocated_slots`).

Frames: ``T_world_part`` 4x4 in metres; yaws in radians.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from asmteach.core.geometry import compose, from_rotation, rot_z
from asmteach.core.hand_geometry import MeshCollider
from asmteach.core.interfaces import PartModel
from asmteach.core.models import Placement
from asmteach.plugins.planners.regrasp.graph import PoseSlot
from asmteach.plugins.planners.regrasp.settings import AssemblySettings

__all__ = ["placement_slots", "relocated_slots"]


def placement_slots(
    placements: Sequence[Placement],
    xy: Sequence[float],
    table_height: float,
    settings: AssemblySettings,
    first: Sequence[np.ndarray] = (),
    every: bool = False,
) -> list[PoseSlot]:
    """Middle-layer slots: the most probable distinct placements at evenly sampled yaws at ``xy``.

    Placements that are the same up to the part's own symmetry (a square peg
    lying on any of its four sides) have the same centre-of-mass height,
    support area and margin; only the first of them is kept.

    ``first``: part orientations ``R_world_part`` (3x3) whose placements come
    first, in the exact variant, whatever their probability: the pose the part
    rests in at the start and the one it stands in at its goal. The grasp set
    is not symmetric like the part, so of a peg's four lying placements only
    the one it lies in shares its grasps from above with the start.

    ``every``: all placements, symmetric duplicates included, whatever
    ``max_placements`` says (the planner's second try).
    """
    chosen: list[Placement] = []
    seen: set[tuple[float, float, float]] = set()
    wanted = [p for R in first if (p := _placement_resting_as(placements, R)) is not None]
    wanted_ids = {p.id for p in wanted}
    by_probability = sorted(placements, key=lambda p: -p.probability)
    for p in wanted + by_probability:
        sig = (round(float(p.T_table_part[2, 3]) * 2000.0), round(_area(p.support_polygon) * 1e6), round(p.margin, 3))
        if p.id in {c.id for c in chosen} or (sig in seen and p.id not in wanted_ids and not every):
            continue
        seen.add(sig)
        chosen.append(p)
    if not every:
        chosen = chosen[: settings.max_placements]
    slots = []
    for p in chosen:
        for k in range(settings.placement_yaws):
            yaw = 2.0 * np.pi * k / settings.placement_yaws
            T = compose(from_rotation(np.eye(3), [xy[0], xy[1], table_height]), rot_z(yaw), p.T_table_part)
            slots.append(PoseSlot(f"placement{p.id}_yaw{round(np.degrees(yaw))}", "middle", T))
    return slots


def relocated_slots(
    slots: Sequence[PoseSlot],
    from_xy: Sequence[float],
    to_xy: Sequence[float],
    part: PartModel,
    collider: MeshCollider,
    clearance: float,
) -> list[PoseSlot]:
    """``slots``, placements made at table position ``from_xy``, moved to ``to_xy`` (world x, y, metres);
    none when the part would come within ``clearance`` metres of any obstacle of ``collider`` but the table
    in any of them. A slot's name gains ``_at{x}_{y}``, ``to_xy`` in millimetres.
    """
    shift = np.asarray(to_xy, float)[:2] - np.asarray(from_xy, float)[:2]
    x, y = (round(float(v) * 1000.0) for v in to_xy[:2])
    out = []
    for slot in slots:
        T = np.asarray(slot.T_world_part, float).copy()
        T[:2, 3] += shift
        if collider.distance(part.mesh, T, skip=("table",)) < clearance:
            return []
        out.append(PoseSlot(f"{slot.name}_at{x}_{y}", slot.layer, T))
    return out


def _placement_resting_as(placements: Sequence[Placement], R_world_part: np.ndarray) -> Placement | None:
    """The placement whose resting direction (part frame) is the table's down in ``R_world_part``, within 3 deg."""
    down = np.asarray(R_world_part, float).T @ np.array([0.0, 0.0, -1.0])
    best, cos = None, np.cos(np.radians(3.0))
    for p in placements:
        c = float(down @ (p.T_table_part[:3, :3].T @ np.array([0.0, 0.0, -1.0])))
        if c > cos:
            best, cos = p, c
    return best


def _area(polygon: np.ndarray) -> float:
    x, y = np.asarray(polygon, float).T
    return 0.5 * abs(float(np.dot(x, np.roll(y, 1)) - np.dot(y, np.roll(x, 1))))
