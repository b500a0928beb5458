"""Stable placements of a part: :func:`compute_placements`, the one stable-rest computation.

The users of resting poses take them from here: the ``stable_placements``
corrector, the grasp planner (grasps spread over the resting poses), the
regrasp planner (intermediate placements), the CVFH detector's resting
hypotheses (:func:`resting_poses`, which also gives each rest's landing
probability, scaled to be drawn from). The random start scenes
(:mod:`asmteach.core.scene`) are the one exception, kept on purpose: see there.

Pipeline (paper, section "Noise correction using geometric constraints"):
convex hull -> support facets (hull faces merged within an angular and a
distance tolerance, :mod:`.facets`) -> stability test with a margin (the
authors' ``d / h``, read as the tilt a rest withstands, so that on a
tessellated curve it counts the facets that roll back: :mod:`.stability`) -> one
:class:`~asmteach.core.models.Placement` per stable facet, with its rotation
(facet on the table, canonical yaw), support polygon, landing probability and
rotational symmetry about the table normal. A merged facet is flat within the
tolerances, so the part rests on the plane of its mean normal. The rule is
checked against PyBullet drops by the placements plugin's ``drop_test`` (and
over the part corpus by ``benchmarks/placements_drop.py``).

A rest with nothing to topple over (its basin is the whole sphere of down
directions) is reported with margin :data:`NO_TOPPLE_MARGIN`.

Frames: ``T_table_part`` maps part-frame points (metres) into the table frame
(z up, table surface z = 0). Canonical yaw: the rotation has fixed-axis yaw 0
(``R = Ry(pitch) Rx(roll)``), and the COM sits above the table origin.
Results are cached in memory per (mesh hash, COM, settings).
"""

from __future__ import annotations

import logging
import math
import time
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import trimesh

from asmteach.core import geometry
from asmteach.core.errors import UserError
from asmteach.core.interfaces import PartModel
from asmteach.core.models import Placement
from asmteach.core.parts import mesh_hash
from asmteach.core.rests.facets import (
    MERGE_DIST_REL,
    Hull,
    SupportFacets,
    convex_hull,
    is_closed,
    support_facets,
)
from asmteach.core.rests.stability import FacetStability, facet_stability
from asmteach.core.symmetry import SymmetryFinder, symmetry_yaws

__all__ = [
    "NO_TOPPLE_MARGIN",
    "PlacementResult",
    "RejectedFacet",
    "canonical_rotation",
    "clear_cache",
    "compute_placements",
    "plan_placements",
    "resting_poses",
]

log = logging.getLogger(__name__)

_CACHE_SIZE = 64
# Reported margin of a rest with nothing to topple over (its basin is every down direction: see stability).
NO_TOPPLE_MARGIN = 100.0
_cache: OrderedDict[tuple[Any, ...], PlacementResult] = OrderedDict()
_warned: set[str] = set()


@dataclass
class RejectedFacet:
    """A facet that holds the part (COM inside) but fails the margin test."""

    normal: list[float]
    margin: float
    probability: float
    reason: str


@dataclass
class PlacementResult:
    """Placements of one part plus what was rejected and how long it took.

    ``convex`` is the convex hull (part frame, metres; :attr:`hull` views it
    as a mesh); ``facets`` and ``stability`` are the per-facet figures;
    ``seconds`` the planning time (symmetry included) of the computation that
    filled the cache.
    """

    placements: list[Placement]
    rejected: list[RejectedFacet]
    convex: Hull
    center_of_mass: np.ndarray
    facets: SupportFacets
    stability: FacetStability
    facet_of_placement: list[int]
    seconds: float
    notes: list[str] = field(default_factory=list)

    @property
    def hull(self) -> trimesh.Trimesh:
        """The convex hull as a watertight mesh (part frame, metres)."""
        return self.convex.mesh


def canonical_rotation(normal: np.ndarray) -> np.ndarray:
    """``(3, 3)`` rotation taking the outward facet ``normal`` (part frame) to ``-z``, with rpy yaw 0.

    With ``R = Ry(pitch) Rx(roll)`` the part-frame up vector ``u = -normal`` is
    ``R``'s last row ``(-sin p, cos p sin r, cos p cos r)``, which gives roll and
    pitch in closed form (roll 0 when ``u`` is along x, where it is free).
    """
    u = -np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    # Scalar math: this runs once per placement and numpy's per-call cost dominates 3-vectors.
    pitch = -math.asin(min(1.0, max(-1.0, float(u[0]))))
    roll = math.atan2(float(u[1]), float(u[2])) if math.hypot(float(u[1]), float(u[2])) > 1e-12 else 0.0
    cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
    # Ry(pitch) @ Rx(roll), multiplied out.
    return np.array([[cp, sp * sr, sp * cr], [0.0, cr, -sr], [-sp, cp * sr, cp * cr]])


def _support_polygon(points_table: np.ndarray) -> np.ndarray:
    """Counter-clockwise support polygon of table-frame contact points (``(n, 2)``, metres).

    The contact points are the vertices of one face of a convex polytope, so
    they are in convex position: sorting them by angle about their centroid
    orders the polygon (no hull computation needed).
    """
    xy = points_table[:, :2]
    c = xy.mean(axis=0)
    order = np.argsort(np.arctan2(xy[:, 1] - c[1], xy[:, 0] - c[0]), kind="stable")
    return xy[order]


def _axis_order(finder: SymmetryFinder | None, normal: np.ndarray, memo: dict[tuple[float, ...], int]) -> int:
    """Symmetry order about the axis along ``normal``; opposite facets share an axis."""
    if finder is None:
        return 1
    axis = normal if (normal[np.argmax(np.abs(normal))] > 0) else -normal
    key = tuple(np.round(axis, 6).tolist())
    if key not in memo:
        memo[key] = finder.order(axis)
    return memo[key]


def plan_placements(
    mesh: trimesh.Trimesh,
    center_of_mass: np.ndarray | None = None,
    *,
    min_margin: float = 0.1,
    angle_tol_deg: float = 1.0,
    merge_dist_rel: float = MERGE_DIST_REL,
    roll_angle_deg: float = 15.0,
    min_probability: float = 0.0,
    symmetry: bool = True,
    max_symmetry_order: int = 36,
    name: str = "the mesh",
) -> PlacementResult:
    """Compute the stable placements of ``mesh`` (no cache).

    Parameters
    ----------
    mesh : part mesh, part frame, metres. An open mesh is replaced by its hull (warned once).
    center_of_mass : ``(3,)`` part frame, metres; default: the mesh's (or its hull's, if open).
    min_margin : smallest ``d / h`` of a stable placement (dimensionless).
    angle_tol_deg : faces whose normals differ by less are one support facet.
    merge_dist_rel : faces whose vertices lie within this fraction of the part's largest extent of an
        adjacent face's plane are one support facet (see :mod:`.facets`).
    roll_angle_deg : largest dihedral angle, degrees, across which a weak facet rolls down a curve or
        level rests form one neutral family (see :mod:`.stability`); 0 turns curved rests off.
    min_probability : placements less likely than this are dropped (0 keeps every stable one).
    symmetry : find each placement's rotational symmetry about the table normal.
    name : how messages refer to the part.

    Raises :class:`UserError` for flat or degenerate meshes and a COM outside the hull.
    """
    t0 = time.perf_counter()
    notes: list[str] = []
    closed = is_closed(mesh.faces)
    if not closed:
        key = mesh_hash(mesh)
        if key not in _warned:
            _warned.add(key)
            log.warning("%s is not watertight; placements use its convex hull", name)
        notes.append("mesh not watertight: convex hull used")
    hull = convex_hull(mesh, name=name)
    if center_of_mass is None:
        center_of_mass = mesh.center_mass if closed else hull.center_mass
    com = np.asarray(center_of_mass, dtype=float)
    if com.shape != (3,) or not np.all(np.isfinite(com)):
        raise UserError(f"{name}: the centre of mass must be three finite numbers (metres), got {com.tolist()}")
    hv = hull.vertices
    outside = float(np.max(hull.normals @ com - np.einsum("ij,ij->i", hull.normals, hv[hull.faces[:, 0]])))
    if outside >= 0.0:
        raise UserError(
            f"{name}: the centre of mass {np.round(com, 6).tolist()} m lies outside the convex hull "
            f"(by {outside * 1000:.3f} mm); give it in the part frame, in metres"
        )
    facets = support_facets(
        hull, angle_tol=np.radians(angle_tol_deg), merge_dist=merge_dist_rel * float(np.ptp(hv, axis=0).max())
    )
    stab = facet_stability(facets, com, min_margin=min_margin, roll_angle=np.radians(roll_angle_deg))

    keep = np.flatnonzero(stab.stable & (stab.probability >= min_probability))
    keep = keep[np.lexsort((-stab.margin[keep], -stab.probability[keep]))]
    finder = SymmetryFinder(mesh, hv, com, max_order=max_symmetry_order) if symmetry else None
    placements: list[Placement] = []
    kept: list[int] = []
    orders: dict[tuple[float, ...], int] = {}
    for c in keep:
        # A merged facet is flat within the tolerances: the part rests on the plane of its mean normal,
        # on the facet's boundary vertices.
        normal = facets.normals[c]
        margin = float(min(stab.margin[c], NO_TOPPLE_MARGIN))
        contacts = facets.vertices[facets.edges[facets.edge_cluster == c, 0]]
        R = canonical_rotation(normal)
        pts = hv @ R.T
        t = np.array([-(R @ com)[0], -(R @ com)[1], -pts[:, 2].min()])
        T = geometry.from_rotation(R, t)
        contact = geometry.transform_points(T, contacts)
        order = _axis_order(finder, normal, orders)
        # Built from validated parts (T is a proper rotation by construction), so pydantic's
        # per-field validation, which costs as much as the rest of the loop, is skipped.
        placements.append(
            Placement.model_construct(
                id=len(placements),
                T_table_part=T,
                probability=float(np.clip(stab.probability[c], 0.0, 1.0)),
                margin=margin,
                support_polygon=_support_polygon(contact),
                symmetry_yaws=symmetry_yaws(order),
            )
        )
        kept.append(int(c))
    rejected = [
        RejectedFacet(
            normal=facets.normals[c].round(6).tolist(),
            margin=float(stab.margin[c]),
            probability=float(stab.probability[c]),
            reason=(
                f"rolls down the curve to the rest on facet {stab.topple_to[c]} (d/h here {stab.margin[c]:.3f})"
                if stab.topple_to[c] != c
                else f"margin {stab.margin[c]:.3f} < {min_margin}"
                if not stab.stable[c]
                else f"probability {stab.probability[c]:.3g} < {min_probability}"
            ),
        )
        for c in np.flatnonzero(stab.holds & ~np.isin(np.arange(facets.count), keep))
    ]
    if not placements:
        notes.append("no facet passes the stability test")
    return PlacementResult(
        placements=placements,
        rejected=rejected,
        convex=hull,
        center_of_mass=com,
        facets=facets,
        stability=stab,
        facet_of_placement=kept,
        seconds=time.perf_counter() - t0,
        notes=notes,
    )


def placement_result(part: PartModel, **kwargs: Any) -> PlacementResult:
    """Cached :func:`plan_placements` for a :class:`PartModel` (key: mesh hash, COM, settings)."""
    key = (
        part.source_hash or mesh_hash(part.mesh),
        tuple(np.round(np.asarray(part.center_of_mass, dtype=float), 9).tolist()),
        tuple(sorted(kwargs.items())),
    )
    hit = _cache.get(key)
    if hit is None:
        hit = plan_placements(part.mesh, part.center_of_mass, name=f"part {part.name!r}", **kwargs)
        _cache[key] = hit
        while len(_cache) > _CACHE_SIZE:
            _cache.popitem(last=False)
    else:
        _cache.move_to_end(key)
    return hit


def compute_placements(part: PartModel, **kwargs: Any) -> list[Placement]:
    """Stable placements of ``part``, most probable first (ids ``0..n-1``).

    Keyword arguments are those of :func:`plan_placements`. Computed once per
    part and settings, then served from memory (as deep copies).
    """
    return [p.model_copy(deep=True) for p in placement_result(part, **kwargs).placements]


def clear_cache() -> None:
    """Forget every cached placement set."""
    _cache.clear()


def _level_x_rotation(up: np.ndarray) -> np.ndarray:
    """``(3, 3)`` rotation taking the part-frame ``up`` (unit) to +z, its rows ``x, y, up`` with
    ``x = (-up_y, up_x, 0)`` normalised (``(1, 0, 0)`` when ``up`` is along z).

    This yaw is the one ``trimesh.poses.compute_stable_poses`` gives (its rests
    match these to 1e-16 on the set-1 and set-2 parts), so hypotheses and
    scenes built on it before stay where they were.
    """
    z = np.asarray(up, dtype=float) / np.linalg.norm(up)
    x = np.array([-z[1], z[0], 0.0])
    n = float(np.linalg.norm(x))
    x = np.array([1.0, 0.0, 0.0]) if n == 0.0 else x / n
    y = np.cross(z, x)
    return np.array([x, y / np.linalg.norm(y), z])


def resting_poses(
    placements: Sequence[Placement], vertices: np.ndarray, min_probability: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """``(T (k, 4, 4), probabilities (k,))``: the placements as part poses resting on the plane z = 0.

    Each ``T`` maps part-frame points (metres) to the resting frame with the
    footprint (the bounding box of ``vertices`` in x and y) centred on
    ``x = y = 0`` and the yaw of :func:`_level_x_rotation`, most likely first. Only placements at least
    ``min_probability`` likely are kept (the most likely one always is), and
    their landing probabilities are scaled to sum to 1 so that a random start
    pose can be drawn from them (refused facets hold the part too, so the
    reported probabilities alone may sum to less).
    """
    if not placements:
        return np.zeros((0, 4, 4)), np.zeros(0)
    p = np.array([pl.probability for pl in placements], dtype=float)
    order = np.argsort(-p, kind="stable")
    keep = order[p[order] >= min(min_probability, float(p.max()))]
    v = np.asarray(vertices, dtype=float)
    out = []
    for i in keep:
        T = geometry.from_rotation(_level_x_rotation(np.asarray(placements[i].T_table_part, dtype=float)[2, :3]))
        w = geometry.transform_points(T, v)
        c = 0.5 * (w.min(axis=0) + w.max(axis=0))
        out.append(geometry.compose(geometry.from_rotation(np.eye(3), [-c[0], -c[1], -w[:, 2].min()]), T))
    prob = p[keep]
    prob = prob / prob.sum() if prob.sum() > 0.0 else np.full(len(keep), 1.0 / len(keep))
    return np.asarray(out).reshape(-1, 4, 4), prob
