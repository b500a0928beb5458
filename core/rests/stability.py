"""Stability of support facets and the quasi-static probability of landing on each.

Stability test (the authors' own rule): a facet is a stable placement when the
centre of mass (COM), projected along the facet normal onto the support plane,
lies inside the support polygon with ``d / h >= min_margin``, where ``d`` is
the distance from the projection to the nearest polygon edge and ``h`` the
height of the COM above the plane (default ``min_margin = 0.1``). Facets are
the merged hull faces of :mod:`.facets` (angular and distance tolerances).

The margin as a tilt. ``d / h`` is the tangent of the smallest tilt that
takes a resting part out of its rest: tilted about a horizontal axis, it
comes back while the COM stays over the support, and the plane through the
COM and an edge at distance ``d`` leans ``atan(d / h)`` from the vertical.
The same statement holds on the sphere of down directions, where each facet
owns the directions whose ray from the COM crosses it (the partition of the
probability model below): a part tilted from its rest comes back as long as
the down direction stays in the rest's *basin*, the cells of the facets that
flow back to it. So the margin of a rest is ``tan`` of the angle from its
normal to the basin's boundary. For a facet whose neighbours all flow
elsewhere (any sharp-edged part) the basin is its own cell and the margin is
exactly the authors' ``d / h``; the rule only differs on tessellated curves:

* a facet that does not hold the COM topples across one edge (below); a
  facet that holds it with ``d / h`` below the margin and has a *lower*
  neighbour across a shallow edge (dihedral below ``roll_angle``, default
  15 degrees) that holds too is no rest of its own: the part rolls down the
  curve to it. (A facet that passes the authors' rule on its own is always
  a rest, and its margin can only grow with its basin.) Following these
  steps gives each facet its rest, and the basin of a rest is every facet
  that ends there. A duck's belly: the hull faces around the lowest one
  flow back to it, so it rests there with a wide basin although the lowest
  face alone has ``d / h`` of a few hundredths; a D-peg on its round side
  rests on its lowest strip only (the strips above it roll down to it).
* rests joined by a shallow edge at the same COM height (within
  ``_LEVEL_REL``) are one neutral family, one basin: a cylinder lying on its
  side rolls from strip to strip without toppling. Every strip is reported
  (each is a rest the part stays in), with the family's margin (tilting it
  over an end cap: ``(L / 2) / r`` for a centred COM), although a single
  strip of a 64-gon has ``d / h = tan(pi / 64) = 0.05`` across it.

A rest whose basin is the whole sphere (nothing to topple over) has an
infinite margin. Why 15 degrees: a regular ``n``-gon prism has
``d / h = tan(pi / n)`` on its sides, below 0.1 exactly when ``n > 31``,
i.e. when its dihedral angles ``2 pi / n`` are below 11.6 degrees; from 12
sides (30 degrees) up the sides pass on ``d / h`` alone. A tall post
standing on its end is refused as before. PyBullet drops and tilted
releases (the placements plugin's ``drop_test``) are the judge: released tilted by less than
``atan(min_margin)`` a reported rest keeps the part (or lets a cylinder roll
to a neighbouring strip), and the rests the drops find on refused facets let
it go when tilted by more.

Probability: a part dropped in a uniformly random orientation first lands on
the facet whose solid angle (seen from the COM) contains the down direction;
if the COM projection lies outside that facet the part topples across the
edge the projection crossed onto the neighbouring facet, and so on until a
facet holds it (Goldberg et al., "Part pose statistics", 1999). Toppling
lowers the COM, so the graph has no cycle. Facets where the COM is inside but
the margin is below ``min_margin`` (or that roll down to another rest) hold the
part too (they are sinks) but are not reported as placements, so reported
probabilities may sum to less than 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from asmteach.core.rests.facets import SupportFacets, _components, cross

# Relative COM-height tolerance of a neutral roll (a cylinder's strips are level to rounding).
_LEVEL_REL = 1e-4

__all__ = ["DirectionStability", "FacetStability", "evaluate_direction", "facet_stability", "plane_basis"]


@dataclass
class FacetStability:
    """Per-facet stability figures (arrays of length ``C``, the facet count).

    ``height``: COM height above the support plane (m); ``margin``: of a rest, ``tan`` of the
    smallest tilt out of its basin (module docstring; ``inf`` when nothing to topple over), else
    the plain ``d / h``; ``distance``: ``margin * height`` (m) where the COM projection is inside,
    else the signed distance (negative) to the nearest edge line; ``stable``: a rest (holds and
    rolls to no lower neighbour) with ``margin >= min_margin``; ``rolls``: a rest whose basin has
    other facets (a curve);
    ``basin``: label of the basin each facet ends in (rests with one label are one neutral family,
    e.g. the strips of a cylinder on its side: a consumer may keep a few of them);
    ``holds``: the COM projection is inside (a sink of the toppling graph);
    ``topple_to``: the rest the part ends on from this facet, toppling and rolling down (itself for rests);
    ``solid_angle``: steradians seen from the COM; ``probability``: of ending on each facet.
    """

    height: np.ndarray
    distance: np.ndarray
    margin: np.ndarray
    stable: np.ndarray
    rolls: np.ndarray
    basin: np.ndarray
    holds: np.ndarray
    topple_to: np.ndarray
    solid_angle: np.ndarray
    probability: np.ndarray


def _solid_angles(triangles: np.ndarray, apex: np.ndarray) -> np.ndarray:
    """Solid angle (sr) of each ``(F, 3, 3)`` triangle seen from ``apex`` (Van Oosterom-Strackee)."""
    r = triangles - apex
    length = np.linalg.norm(r, axis=2)
    a, b, c = r[:, 0], r[:, 1], r[:, 2]
    la, lb, lc = length[:, 0], length[:, 1], length[:, 2]
    num = np.einsum("ij,ij->i", a, cross(b, c))
    den = (
        la * lb * lc
        + np.einsum("ij,ij->i", a, b) * lc
        + np.einsum("ij,ij->i", a, c) * lb
        + np.einsum("ij,ij->i", b, c) * la
    )
    return 2.0 * np.abs(np.arctan2(num, den))


def _first_per_group(groups: np.ndarray, key: np.ndarray, n_groups: int) -> np.ndarray:
    """Index of the smallest ``key`` within each group (-1 for empty groups)."""
    order = np.lexsort((key, groups))
    g_sorted = groups[order]
    first = np.ones(len(order), dtype=bool)
    first[1:] = g_sorted[1:] != g_sorted[:-1]
    out = np.full(n_groups, -1, dtype=np.int64)
    out[g_sorted[first]] = order[first]
    return out


def facet_stability(
    facets: SupportFacets, com: np.ndarray, *, min_margin: float = 0.1, roll_angle: float = np.radians(15.0)
) -> FacetStability:
    """Stability and landing probability of every facet for a COM (part frame, metres).

    ``roll_angle`` (radians): largest dihedral across which a weak facet rolls down a curve or level
    rests join one neutral family; 0 gives every facet its own basin (the plain ``d / h``).
    """
    com = np.asarray(com, dtype=float)
    n_c = facets.count
    height = facets.offsets - facets.normals @ com
    proj = com + height[:, None] * facets.normals  # COM projected onto each support plane

    # Signed distance of the projection to each boundary edge line (positive on the facet side).
    v = facets.vertices
    a = v[facets.edges[:, 0]]
    b = v[facets.edges[:, 1]]
    n_e = facets.normals[facets.edge_cluster]
    inward = cross(n_e, b - a)
    inward /= np.linalg.norm(inward, axis=1, keepdims=True)
    p_e = proj[facets.edge_cluster]
    s = np.einsum("ij,ij->i", p_e - a, inward)
    distance = np.full(n_c, np.inf)
    np.minimum.at(distance, facets.edge_cluster, s)
    holds = distance >= 0.0

    # Toppling edge of a non-holding facet: the edge crossed by the ray from the facet
    # centroid to the COM projection (the projection lies in the wedge centroid-a-b).
    face_area = facets.face_areas
    centroid = np.zeros((n_c, 3))
    np.add.at(centroid, facets.face_cluster, facets.face_centers * face_area[:, None])
    centroid /= np.maximum(facets.areas, 1e-300)[:, None]
    g = centroid[facets.edge_cluster]
    w1 = np.einsum("ij,ij->i", cross(a - g, p_e - g), n_e)
    w2 = np.einsum("ij,ij->i", cross(p_e - g, b - g), n_e)
    in_wedge = (w1 >= 0.0) & (w2 >= 0.0) & (s < 0.0)
    # Prefer wedge edges, then the most violated edge (a numerical fallback).
    key = np.where(in_wedge, -1e9, 0.0) + s
    best_edge = _first_per_group(facets.edge_cluster, key, n_c)
    topple = np.arange(n_c)
    falls = ~holds & (best_edge >= 0)
    topple[falls] = facets.edge_neighbor[best_edge[falls]]

    # Basins (module docstring). A facet that holds rolls on to its lowest shallow neighbour that holds
    # when that is lower (by more than _LEVEL_REL); one that does not hold topples across one edge.
    own, nb = facets.edge_cluster, facets.edge_neighbor
    shallow = np.einsum("ij,ij->i", facets.normals[own], facets.normals[nb]) > np.cos(roll_angle)
    safe_h = np.maximum(height, 1e-12)
    # Only a facet that fails the rule on its own rolls on: with d / h >= min_margin it is a rest whatever
    # its neighbours, as the authors' rule says.
    weak = holds & (distance / safe_h < min_margin)
    lower = shallow & weak[own] & holds[nb] & (height[nb] < height[own] * (1.0 - _LEVEL_REL))
    step = topple.copy()
    if lower.any():
        e = _first_per_group(own[lower], height[nb[lower]], n_c)
        has = e >= 0
        step[has] = nb[lower][e[has]]
    root = step.copy()  # follow the chains to their ends by pointer jumping
    for _ in range(int(np.ceil(np.log2(max(n_c, 2)))) + 2):
        root = root[root]
    loop = root[root] != root  # numerical ties that form a cycle: stop where they are
    root[loop] = np.flatnonzero(loop)
    rest = holds & (root == np.arange(n_c))
    # Rests joined by a shallow edge at the same COM height are one neutral family (a cylinder's strips).
    level = shallow & rest[own] & rest[nb] & (np.abs(height[nb] - height[own]) <= _LEVEL_REL * height[own])
    _, family_of = _components(n_c, own[level], nb[level])
    basin = family_of[root]
    # Margin of a rest: tan of the smallest tilt that takes the part out of its basin, i.e. the angle from
    # its normal to the basin's boundary on the sphere of down directions: the planes through the COM and
    # the hull edges between the basin and the rest (Goldberg's partition). A single facet's basin gives
    # d / h exactly (the plane through the COM and an edge at distance d leans atan(d / h)).
    edge_out = basin[own] != basin[nb]
    pa = v[facets.edges[edge_out, 0]] - com
    pb_ = v[facets.edges[edge_out, 1]] - com
    pa /= np.linalg.norm(pa, axis=1, keepdims=True)
    pb_ /= np.linalg.norm(pb_, axis=1, keepdims=True)
    m = cross(pa, pb_)
    m /= np.maximum(np.linalg.norm(m, axis=1, keepdims=True), 1e-300)
    out_basin = basin[own[edge_out]]
    angle = np.full(n_c, np.inf)
    for f in np.flatnonzero(rest):
        sel = out_basin == basin[f]
        if not sel.any():
            continue  # the whole sphere flows here: nothing to topple over
        n = facets.normals[f]
        nm = m[sel] @ n
        q = n - nm[:, None] * m[sel]  # n projected on each plane
        inside = (np.einsum("ij,ij->i", cross(pa[sel], q), m[sel]) >= 0.0) & (
            np.einsum("ij,ij->i", cross(q, pb_[sel]), m[sel]) >= 0.0
        )
        to_arc = np.where(
            inside,
            np.arcsin(np.clip(np.abs(nm), 0.0, 1.0)),
            np.arccos(np.clip(np.minimum(np.maximum(pa[sel] @ n, pb_[sel] @ n), 1.0), -1.0, 1.0)),
        )
        angle[f] = float(to_arc.min())
    # Facets that hold but are no rest of their own (they roll down to one) keep their plain d / h.
    margin = np.where(rest, np.tan(np.minimum(angle, np.pi / 2 - 1e-12)), distance / safe_h)
    margin = np.where(rest & ~np.isfinite(angle), np.inf, margin)
    distance = np.where(holds, margin * safe_h, distance)
    rolls = rest & (np.bincount(basin, minlength=n_c)[basin] > 1)
    stable = rest & (margin >= min_margin)

    solid_f = _solid_angles(facets.vertices[facets.faces], com)
    solid = np.bincount(facets.face_cluster, weights=solid_f, minlength=n_c)
    prob = np.bincount(root, weights=solid, minlength=n_c) / max(solid.sum(), 1e-300)
    return FacetStability(
        height=height,
        distance=distance,
        margin=margin,
        stable=stable,
        rolls=rolls,
        basin=basin,
        holds=holds,
        topple_to=root,
        solid_angle=solid,
        probability=prob,
    )


def plane_basis(normal: np.ndarray) -> np.ndarray:
    """``(2, 3)`` orthonormal in-plane axes ``(u, v)`` with ``u x v = normal``."""
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = cross(helper, n)
    u /= np.linalg.norm(u)
    return np.stack([u, cross(n, u)])


@dataclass
class DirectionStability:
    """Stability of the part resting on the supporting plane with outward normal ``normal``.

    ``contacts``: ``(k, 3)`` hull points on the plane; ``polygon``: ``(m, 2)`` support polygon
    in :func:`plane_basis` coordinates (empty when the contact is a point or an edge);
    ``distance`` (m, positive inside), ``height`` (m) and ``margin = distance / height``.
    """

    normal: np.ndarray
    contacts: np.ndarray
    polygon: np.ndarray
    distance: float
    height: float
    margin: float


def evaluate_direction(
    vertices: np.ndarray, com: np.ndarray, normal: np.ndarray, *, tol: float | None = None
) -> DirectionStability:
    """Independent stability test for one resting direction (no facet clustering).

    The supporting plane with outward normal ``normal`` touches the points of
    ``vertices`` (hull vertices, part frame, metres) within ``tol`` of the
    farthest one (default ``1e-6`` of the part's size); their 2-D convex hull
    is the support polygon. Used to check our placements and trimesh's poses
    with the same rule.
    """
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    vertices = np.asarray(vertices, dtype=float)
    if tol is None:
        tol = 1e-6 * float(np.ptp(vertices, axis=0).max())
    d = vertices @ n
    top = d.max()
    contacts = vertices[d >= top - tol]
    height = float(top - np.asarray(com, dtype=float) @ n)
    basis = plane_basis(n)
    pts = contacts @ basis.T
    c2 = basis @ np.asarray(com, dtype=float)
    empty = np.zeros((0, 2))
    if len(pts) < 3:
        return DirectionStability(n, contacts, empty, -np.inf, height, -np.inf)
    try:
        ch = ConvexHull(pts)
    except QhullError:  # collinear contacts: an edge, not a polygon
        return DirectionStability(n, contacts, empty, -np.inf, height, -np.inf)
    # equations: outward unit normal (2) and offset; inside points give n.x + off <= 0.
    dist = float(np.min(-(ch.equations[:, :2] @ c2 + ch.equations[:, 2])))
    return DirectionStability(n, contacts, pts[ch.vertices], dist, height, dist / max(height, 1e-12))
