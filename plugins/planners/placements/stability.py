"""Stability of support facets and the quasi-static probability of landing on each.

Stability test (the authors' own rule): a facet is a stable placement when the
centre of mass (COM), projected along the facet normal onto the support plane,
lies inside the support polygon with ``d / h >= min_margin``, where ``d`` is
the distance from the projection to the nearest polygon edge and ``h`` the
height of the COM above the plane (default ``min_margin = 0.1``). Facets are
the merged hull faces of :mod:`.facets` (angular and distance tolerances).

Curved parts (rolling edges). A tessellated curve gives hull facets that are
thin strips (a 64-gon cylinder on its side: ``d / h = tan(pi / 64) = 0.05``
across the strip) or small patches (a duck's belly). Tipping such a part over
a strip's long edge does not topple it: it rolls onto the next strip of the
same curve and stays there (a cylinder: neutral) or rolls back (a belly:
the COM rises). So an edge is a *rolling edge* when the facet across it is
within ``roll_angle`` (default 15 degrees) of this one and either topples
back onto this facet or holds the COM with ``d / h >= min_margin`` against
its own steep edges (dihedral of ``roll_angle`` or more: the ones it could
topple over; a strip next to a D-peg's flat is not such a facet, so its
neighbours are measured against the edge onto it) with the COM no lower
there (a neutral or uphill roll; rolling downhill leaves the rest: the
strips of a D-peg above its lowest one); ``d`` is measured to the other
edges only, the ones the part can topple over (the cylinder's end caps).
A facet that holds the COM with every edge a rolling edge has nothing to
topple over: its ``distance`` is infinite. Why 15 degrees: a regular
``n``-gon prism has ``d / h = tan(pi / n)`` on its sides, below 0.1 exactly
when ``n > 31``, i.e. when its dihedral angles ``2 pi / n`` are below
11.6 degrees; from 12 sides (30 degrees) up the sides pass on ``d / h`` alone.
A tall post standing on its end (edges of 90 degrees) is refused as before.
PyBullet drops (:mod:`.drop_test`) settle a cylinder on a strip, a duck on
its belly: the rests this rule reports.

Probability: a part dropped in a uniformly random orientation first lands on
the facet whose solid angle (seen from the COM) contains the down direction;
if the COM projection lies outside that facet the part topples across the
edge the projection crossed onto the neighbouring facet, and so on until a
facet holds it (Goldberg et al., "Part pose statistics", 1999). Toppling
lowers the COM, so the graph has no cycle. Facets where the COM is inside but
the margin is below ``min_margin`` hold the part too (they are sinks) but are
not reported as placements, so reported probabilities may sum to less than 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from asmteach.plugins.planners.placements.facets import SupportFacets, cross

# Relative COM-height tolerance of a neutral roll (a cylinder's strips are level to rounding).
_LEVEL_REL = 1e-4

__all__ = ["DirectionStability", "FacetStability", "evaluate_direction", "facet_stability", "plane_basis"]


@dataclass
class FacetStability:
    """Per-facet stability figures (arrays of length ``C``, the facet count).

    ``height``: COM height above the support plane (m); ``distance``: signed distance
    (m) from the projected COM to the nearest edge line the part can topple over
    (rolling edges left out: see the module docstring), positive inside, ``inf``
    when every edge is a rolling edge; ``margin``: ``distance / height``;
    ``stable``: ``margin >= min_margin``; ``rolls``: the facet has rolling edges;
    ``holds``: the COM projection is inside (a sink of the toppling graph);
    ``topple_to``: facet reached by toppling (itself for sinks);
    ``solid_angle``: steradians seen from the COM; ``probability``: of ending on each facet.
    """

    height: np.ndarray
    distance: np.ndarray
    margin: np.ndarray
    stable: np.ndarray
    rolls: np.ndarray
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

    ``roll_angle`` (radians): largest dihedral of a rolling edge; 0 measures ``d`` to every edge.
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

    # Follow the toppling chains to their sinks by pointer jumping.
    final = topple.copy()
    for _ in range(int(np.ceil(np.log2(max(n_c, 2)))) + 2):
        final = final[final]
    stuck = final[final] != final  # numerical ties that form a cycle: stop where they are
    final[stuck] = np.flatnonzero(stuck)

    # Rolling edges of holding facets: onto a facet within roll_angle that topples back, or that holds
    # and passes the rule against its own steep edges (the ones it could topple over).
    own, nb = facets.edge_cluster, facets.edge_neighbor
    shallow = np.einsum("ij,ij->i", facets.normals[own], facets.normals[nb]) > np.cos(roll_angle)
    safe_h = np.maximum(height, 1e-12)
    steep_d = np.full(n_c, np.inf)
    np.minimum.at(steep_d, own[~shallow], s[~shallow])
    firm = holds & (steep_d / safe_h >= min_margin)
    # Rolling onto a firm facet must not lower the COM (a neutral or uphill roll): on a D-peg lying on its
    # round side the strips above the lowest one roll down toward it, so they are not rests of their own.
    level = height[nb] >= height[own] * (1.0 - _LEVEL_REL)
    rolling = holds[own] & shallow & ((final[nb] == own) | (firm[nb] & level))
    distance = np.where(holds, np.inf, distance)
    np.minimum.at(distance, own[~rolling & holds[own]], s[~rolling & holds[own]])
    rolls = np.bincount(own[rolling], minlength=n_c) > 0
    margin = distance / safe_h
    stable = margin >= min_margin

    solid_f = _solid_angles(facets.vertices[facets.faces], com)
    solid = np.bincount(facets.face_cluster, weights=solid_f, minlength=n_c)
    prob = np.bincount(final, weights=solid, minlength=n_c) / max(solid.sum(), 1e-300)
    return FacetStability(
        height=height,
        distance=distance,
        margin=margin,
        stable=stable,
        rolls=rolls,
        holds=holds,
        topple_to=final,
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
