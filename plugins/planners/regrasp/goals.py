"""Where the assembly happens: part A's goal on the table, B's assembled and pre-assembly poses.

Part A is put down in one of its stable placements at a chosen spot of the
table; the placements are ranked by how nearly vertical they make B's
insertion (``v_a`` pointing down in the world), so that it is a straight
move down, with B wholly above the table (:func:`ranked_assembly_goals`; the
planner takes the first at which enough of B's grasps are feasible). B's goal
is ``T_world_A @ T_A_B``; its pre-assembly pose is that goal moved back
along ``-v_a`` by the retraction distance (the paper's narrow-passage fix),
or further where B would otherwise still be inside A (:func:`clear_retraction`).

A taught ``v_a`` within :data:`VERTICAL_SNAP` of the table normal at the
chosen placement is taken as exactly vertical: the insertion line passes
through B's goal, so a direction error of e radians puts B ``depth * tan(e)``
off the hole's axis where it enters (0.87 deg of teaching noise: 0.38 mm at a
25 mm deep hole, most of a 0.5 mm clearance), while A resting on a face whose
normal is within a degree or two of the insertion, but not along it, is not a
design anyone makes.

A must stay put while B goes in: a sideways insertion pushes it across the table with up to the guarded
insertion's force limit (:func:`a_under_insertion`); the placements where it resists rank before those
where it would slide or tip (else A needs holding: a jig, reported as such).

B must also stay where it is let go: a slider in a through slot stood on
end slides down out of it, and a peg in a blind hole deeper than its
insertion drops to the bottom. :func:`slides_out` tells such placements
of A; :func:`ranked_assembly_goals` ranks those where B is held first.

Frames: ``T_world_*`` 4x4, metres; ``v_a`` is a unit vector in A's frame
(the direction B moves *into* the assembly).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import trimesh

from asmteach.core.arm.insertion_records import InsertionSettings
from asmteach.core.errors import UserError
from asmteach.core.geometry import compose, from_rotation, rot_z, transform_points
from asmteach.core.interfaces import PartModel
from asmteach.core.models import AssemblyTask, Placement
from asmteach.core.rests.insertion_load import InsertionStability, insertion_stability

__all__ = [
    "CLEAR_MARGIN",
    "VERTICAL_SNAP",
    "AssemblyGoal",
    "a_under_insertion",
    "assembly_goal_at",
    "choose_assembly_goal",
    "clear_retraction",
    "free_travel",
    "ranked_assembly_goals",
    "slides_out",
    "snap_to_faces",
]

VERTICAL_SNAP = float(np.radians(2.0))
"""Radians: a taught insertion direction this close to straight down at A's goal placement is made straight
down (teaching estimates ``v_a`` to within about 1 deg)."""


@dataclass(frozen=True)
class AssemblyGoal:
    """The assembly's target poses (world frame, metres)."""

    T_world_a: np.ndarray
    T_world_b: np.ndarray
    T_world_b_pre: np.ndarray
    v_world: np.ndarray
    """Insertion direction in the world (unit)."""
    placement_id: int
    """Stable placement of A used at the goal."""
    held: bool = True
    """B stays in A under gravity once let go (:func:`slides_out` is False)."""
    a_load: InsertionStability | None = None
    """What B's insertion, pushing with the guarded insertion's force limit, does to A (:func:`a_under_insertion`)."""


def ranked_assembly_goals(
    part_a: PartModel,
    part_b: PartModel,
    task: AssemblyTask,
    placements_a: Sequence[Placement],
    *,
    xy: Sequence[float],
    yaw: float,
    table_height: float,
    retract: float,
    vertical_snap: float = VERTICAL_SNAP,
) -> list[AssemblyGoal]:
    """A's goal at each of its placements at ``xy`` (metres) turned by ``yaw`` (radians) about the table normal,
    best first: B held in A under gravity (:func:`slides_out`), then A resisting B's insertion unheld
    (:func:`a_under_insertion`), then insertion most nearly straight down, then the likelier placement.

    ``v_world`` is ``R_world_A @ v_a``, or exactly ``(0, 0, -1)`` when that is
    within ``vertical_snap`` radians of it (0 turns the snap off). Placements
    that put the assembled B or its pre-assembly pose below the table are left out.

    Raises :class:`UserError` when no placement of A keeps the assembled B and
    its pre-assembly pose above the table.
    """
    ranked: list[tuple[float, AssemblyGoal]] = []
    T_xy = compose(from_rotation(np.eye(3), [xy[0], xy[1], table_height]), rot_z(yaw))
    for p in placements_a:
        goal = assembly_goal_at(
            part_a, part_b, task, T_xy @ p.T_table_part, p.id, retract=retract, vertical_snap=vertical_snap
        )
        low_b = min(_lowest(part_b, goal.T_world_b), _lowest(part_b, goal.T_world_b_pre))
        if low_b < table_height - 1e-4:
            continue
        held = not slides_out(part_a, part_b, goal.T_world_a, goal.T_world_b, goal.v_world, table_height)
        goal = replace(goal, held=held, a_load=a_under_insertion(part_a, part_b, goal))
        stays = goal.a_load.holds
        ranked.append((8.0 * held + 4.0 * stays + float(-goal.v_world[2]) + 0.05 * p.probability, goal))
    if not ranked:
        raise UserError(
            f"no stable placement of {part_a.name} keeps {part_b.name} above the table when assembled; "
            "check T_A_B and v_a of the structure"
        )
    ranked.sort(key=lambda kg: -kg[0])  # stable: equal keys keep the placements' order
    return [g for _, g in ranked]


def choose_assembly_goal(
    part_a: PartModel,
    part_b: PartModel,
    task: AssemblyTask,
    placements_a: Sequence[Placement],
    *,
    xy: Sequence[float],
    yaw: float,
    table_height: float,
    retract: float,
    vertical_snap: float = VERTICAL_SNAP,
) -> AssemblyGoal:
    """The first of :func:`ranked_assembly_goals`: B's insertion most nearly straight down."""
    return ranked_assembly_goals(
        part_a,
        part_b,
        task,
        placements_a,
        xy=xy,
        yaw=yaw,
        table_height=table_height,
        retract=retract,
        vertical_snap=vertical_snap,
    )[0]


def assembly_goal_at(
    part_a: PartModel,
    part_b: PartModel,
    task: AssemblyTask,
    T_world_a: np.ndarray,
    placement_id: int,
    *,
    retract: float,
    vertical_snap: float = VERTICAL_SNAP,
) -> AssemblyGoal:
    """The goal with A at ``T_world_a`` (metres): B at ``T_world_a @ T_A_B``, its pre-assembly pose behind it.

    The insertion direction is snapped to the nearest of A's plane faces' normals (:func:`snap_to_faces`), then
    to straight down, both within ``vertical_snap`` radians, as :func:`ranked_assembly_goals` does; also used for
    an A already standing somewhere (seen at its goal), to aim B at it.
    """
    v_a = snap_to_faces(np.asarray(task.v_a, float), part_a, vertical_snap)
    T_a = np.asarray(T_world_a, float)
    v_w = T_a[:3, :3] @ v_a
    if float(np.arccos(np.clip(-v_w[2], -1.0, 1.0))) <= vertical_snap:
        v_w = np.array([0.0, 0.0, -1.0])  # teaching noise, not a slanted insertion (module docstring)
    T_b = T_a @ task.T_A_B
    T_pre = T_b.copy()
    T_pre[:3, 3] -= max(retract, clear_retraction(part_a, part_b, T_a, T_b, v_w)) * v_w
    return AssemblyGoal(T_a, T_b, T_pre, v_w, placement_id)


def a_under_insertion(
    part_a: PartModel, part_b: PartModel, goal: AssemblyGoal, force_n: float | None = None
) -> InsertionStability:
    """Whether A, resting at ``goal.T_world_a``, stays put while B is pushed in along ``goal.v_world`` with
    ``force_n`` newtons (default: the guarded insertion's force limit, the most it pushes before it backs off)
    bearing on A at B's assembled centre of mass (world, metres)."""
    force = InsertionSettings().force_limit_n if force_n is None else float(force_n)
    com_b = transform_points(goal.T_world_b, np.asarray(part_b.center_of_mass, float)[None])[0]
    return insertion_stability(part_a, goal.T_world_a, goal.v_world, force, com_b)


FACE_SHARE = 0.02
"""A plane face (coplanar triangles) of at least this share of A's surface area is a design direction a taught
``v_a`` snaps to (a tessellated curve's small triangles are not)."""


def snap_to_faces(v_a: np.ndarray, part_a: PartModel, max_angle: float) -> np.ndarray:
    """Unit ``v_a`` (A's frame), or the normal of one of A's plane faces (:data:`FACE_SHARE`) within ``max_angle``
    radians of its line (either sense; the sense of ``v_a`` kept), the nearest.

    A sideways insertion is taught to about a degree too (T-slider: 0.9 deg), and over a 50 mm slide that puts B
    0.8 mm across a 0.65 mm clearance; a slot, a hole or a groove runs along the normal of A's faces (the end
    faces it opens in), so a taught direction that close to one is taken as it, as straight down is at the goal.
    """
    v = np.asarray(v_a, float) / np.linalg.norm(v_a)
    if max_angle <= 0.0:
        return v
    mesh = part_a.mesh
    area = np.asarray(mesh.area_faces, float)
    normals = [np.asarray(mesh.face_normals, float)[area >= FACE_SHARE * mesh.area]]
    if len(mesh.facets):
        big = np.asarray(mesh.facets_area, float) >= FACE_SHARE * mesh.area
        normals.append(np.asarray(mesh.facets_normal, float)[big])
    n = np.concatenate(normals)
    if not len(n):
        return v
    cos = n @ v
    k = int(np.argmax(np.abs(cos)))
    if abs(cos[k]) < np.cos(max_angle):
        return v
    return np.sign(cos[k]) * n[k] / np.linalg.norm(n[k])


CLEAR_MARGIN = 0.005
"""Metres B stays clear of A along the insertion at its pre-assembly pose."""


def clear_retraction(
    part_a: PartModel, part_b: PartModel, T_world_a: np.ndarray, T_world_b: np.ndarray, v_world: np.ndarray
) -> float:
    """Metres B must move back along ``-v_world`` from ``T_world_b`` to be wholly outside A, plus a margin.

    B is clear of A once their extents along the insertion line no longer overlap: B's
    vertices all lie at least :data:`CLEAR_MARGIN` behind A's hindmost vertex. A fixed retraction
    leaves a slider longer than it still in its slot, and the carry to the pre-assembly pose
    then has to thread a 0.5 mm clearance.
    """
    back = -np.asarray(v_world, float)
    a = transform_points(T_world_a, part_a.mesh.vertices) @ back
    b = transform_points(T_world_b, part_b.mesh.vertices) @ back
    return float(a.max() - b.min()) + CLEAR_MARGIN


SLIDE_PROBE = 0.002
"""Metres B must be free to travel along a downhill direction to count as sliding: the success tolerance."""

SLIDE_SLOPE = float(np.radians(10.0))
"""Radians below horizontal from which B is taken to slide along a free direction (friction holds it on
gentler slopes: 10 deg is well inside the 16.7 deg friction cone of mu = 0.3)."""


SLIDE_TOLERANCE = 0.0005
"""Metres B may stand inside A or off its seat by the taught pose's noise and still rest on it."""


def slides_out(
    part_a: PartModel,
    part_b: PartModel,
    T_world_a: np.ndarray,
    T_world_b: np.ndarray,
    v_world: np.ndarray,
    table_height: float,
    *,
    probe: float = SLIDE_PROBE,
    slope: float = SLIDE_SLOPE,
) -> bool:
    """True when B, let go at ``T_world_b`` in A at ``T_world_a`` (metres), can slide away under gravity.

    B falls if nothing is under it, and slides along its insertion line (``v_world``, unit: on into A, or
    back out), where A leaves it free: straight down and each of the two directions along the line that
    points more than ``slope`` radians below horizontal are tried. B is not held when it can travel
    ``probe`` metres along one before meeting A or the table (:func:`free_travel`). A peg whose head rests
    on A, or whose tip rests on a hole's bottom or the table, is held; a slider in a through slot stood on
    end, a peg in a blind hole deeper than its insertion, or a B taught floating above its seat, is not.
    """
    v = np.asarray(v_world, float) / np.linalg.norm(v_world)
    downhill = [np.array([0.0, 0.0, -1.0])] + [d for d in (v, -v) if d[2] < -np.sin(slope)]
    a = part_a.mesh.copy().apply_transform(np.asarray(T_world_a, float))
    b = part_b.mesh.copy().apply_transform(np.asarray(T_world_b, float))
    return any(free_travel(a, b, d, table_height) >= probe for d in downhill)


def free_travel(a: trimesh.Trimesh, b: trimesh.Trimesh, d: np.ndarray, table_height: float) -> float:
    """Metres mesh ``b`` can move along unit ``d`` before it meets mesh ``a`` or the table (both in the world).

    Rays along ``d`` from B's vertices and face centres to A and to the table plane, and along ``-d`` from
    A's to B: a polyhedron meets another first with a vertex on a face (edge-on-edge contacts are not seen;
    the face centres catch faces flush with each other whose vertices all lie on the other's edges). Each
    ray starts :data:`SLIDE_TOLERANCE` behind its vertex, so a B sunk that far into its seat by the taught
    pose's noise still rests on it. ``inf`` when nothing is in the way.
    """
    d = np.asarray(d, float)
    tol = SLIDE_TOLERANCE
    travel = [np.inf]
    for src, dst, sign in ((b, a, 1.0), (a, b, -1.0)):
        # vertices and face centres: two faces flush with each other may have every vertex on the other's edge
        points = np.concatenate([np.asarray(src.vertices, float), np.asarray(src.triangles_center, float)])
        origins = points - tol * sign * d
        dirs = np.broadcast_to(sign * d, origins.shape)
        loc, ray, _ = dst.ray.intersects_location(origins, dirs, multiple_hits=False)
        if len(ray):
            travel.append(float(np.min(np.einsum("ij,ij->i", loc - origins[ray], dirs[ray]))) - tol)
    if d[2] < 0.0:
        travel.append(float((np.min(b.vertices[:, 2]) - table_height) / -d[2]))
    return max(0.0, min(travel))


def _lowest(part: PartModel, T_world_part: np.ndarray) -> float:
    return float(transform_points(T_world_part, part.mesh.vertices)[:, 2].min())
