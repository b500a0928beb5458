"""The exact route: convex pieces of a parametric solid ``union(add) - union(subtract)`` (part frame, metres)."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, HalfspaceIntersection

from asmteach.core.models import Primitive, SolidSpec

CYLINDER_SECTIONS = 64
"""Sides of the polygon standing in for a cylinder (as in :func:`asmteach.core.parts.build_solid`)."""


def primitive_halfspaces(p: Primitive, sections: int = CYLINDER_SECTIONS) -> np.ndarray:
    """``(m, 4)`` rows ``[n, -d]`` with ``n . x - d <= 0`` inside the primitive (part frame, metres)."""
    if p.shape == "box":
        half = 0.5 * np.asarray(p.size, dtype=float)
        normals = np.vstack([np.eye(3), -np.eye(3)])
        offsets = np.concatenate([half, half])
    else:
        # trimesh's cylinder polygon: vertices at angles 2 pi i / sections, radius r; faces between them.
        ang = 2.0 * np.pi * (np.arange(sections) + 0.5) / sections
        side = np.column_stack([np.cos(ang), np.sin(ang), np.zeros(sections)])
        apothem = float(p.radius) * np.cos(np.pi / sections)
        normals = np.vstack([side, [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]])
        offsets = np.concatenate([np.full(sections, apothem), [0.5 * p.height, 0.5 * p.height]])
    T = np.asarray(p.pose, dtype=float)
    n_world = normals @ T[:3, :3].T
    d_world = offsets + n_world @ T[:3, 3]
    return np.column_stack([n_world, -d_world])


def _interior_point(hs: np.ndarray) -> tuple[np.ndarray, float]:
    """Chebyshev centre and radius (metres) of ``{x : A x + b <= 0}``; radius 0 when empty."""
    A, b = hs[:, :3], hs[:, 3]
    norm = np.linalg.norm(A, axis=1)
    # maximise r subject to A x + r |a| <= -b
    res = linprog(
        c=[0, 0, 0, -1],
        A_ub=np.column_stack([A, norm]),
        b_ub=-b,
        bounds=[(None, None)] * 3 + [(0, None)],
        method="highs",
    )
    if not res.success:
        return np.zeros(3), 0.0
    return res.x[:3], float(res.x[3])


def solid_pieces(solid: SolidSpec, min_thickness: float = 1e-4) -> list[np.ndarray]:
    """Vertices ``(k, 3)`` of convex pieces whose union is the solid (part frame, metres)."""
    # each piece: its halfspaces and an interior point (the Chebyshev centre found when it was accepted)
    pieces = [(hs, _interior_point(hs)[0]) for hs in (primitive_halfspaces(p) for p in solid.add)]
    for cut in solid.subtract:
        C = primitive_halfspaces(cut)
        out: list[tuple[np.ndarray, np.ndarray]] = []
        for hs, centre in pieces:
            if _interior_point(np.vstack([hs, C]))[1] < 0.5 * min_thickness:
                out.append((hs, centre))  # the cut misses this piece
                continue
            for row in C:
                cand = np.vstack([hs, -row])  # outside this face of the cut: n . x >= d
                inner, radius = _interior_point(cand)
                if radius >= 0.5 * min_thickness:
                    out.append((cand, inner))
        pieces = out
    result = []
    for hs, centre in pieces:
        pts = HalfspaceIntersection(hs, centre).intersections
        result.append(pts[ConvexHull(pts).vertices])
    return result
