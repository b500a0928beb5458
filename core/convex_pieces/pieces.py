"""What a convex decomposition depends on, what it gives, and its pieces as hulls and as OBJ text."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh
from scipy.spatial import ConvexHull


@dataclass(frozen=True)
class DecompositionSettings:
    """Everything a decomposition depends on besides the part (the cache key holds all of it)."""

    tolerance: float = 1e-4
    """Largest accepted protrusion and uncovered distance of the convex and plane-split routes, metres."""
    max_pieces: int = 512
    """Most pieces the plane split may make before it gives up on a piece (replaced by its hull); a block
    with two 64-sided holes needs about 200, a plate with four holes about 430."""
    min_coacd_threshold: float = 0.02
    """Lower bound of CoACD's normalised concavity threshold (smaller ones take minutes per part)."""
    coacd_resolution: int = 2000
    """CoACD's surface samples per concavity evaluation."""
    refine_max_pieces: int = 128
    """Most pieces CoACD's result may grow to when its protruding pieces are cut again
    (:mod:`asmteach.core.convex_pieces.refine`), or twice CoACD's count when that is more."""
    seed: int = 0
    """Seed of CoACD's tree search and of the fidelity samples."""
    samples: int = 20000
    """Surface samples for each direction of the fidelity measure."""
    min_thickness: float = 1e-4
    """Pieces of a parametric solid thinner than this (metres) are dropped."""


@dataclass
class ConvexDecomposition:
    """Convex pieces of a part and how faithful they are (part frame, metres)."""

    pieces: list[np.ndarray]
    """Vertices ``(k, 3)`` of each convex piece."""
    method: str
    """``"solid"``, ``"convex"``, ``"plane_split"`` or ``"coacd"`` (see :mod:`asmteach.core.convex_pieces`)."""
    hausdorff: float
    """Two-sided Hausdorff distance between the union of pieces and the mesh, metres (sampled)."""
    protrusion: float
    """Largest distance of a piece's point outside the mesh, metres (sampled; closes clearances)."""
    volume_error: float
    """``|vol(union of pieces) - vol(mesh)| / vol(mesh)``."""
    uncovered: float = 0.0
    """Largest distance of a point of the mesh surface from the pieces, metres (sampled; 0 when covered)."""
    seconds: float = 0.0
    """Time the decomposition and its measurement took when it was built (not when read from the cache)."""
    cached: bool = field(default=False, compare=False)
    """Whether this result was read from the disk cache."""

    def hulls(self) -> list[trimesh.Trimesh]:
        """Each piece as a closed convex ``trimesh.Trimesh`` (its hull)."""
        return [piece_hull(v) for v in self.pieces]

    def obj(self) -> str:
        """Wavefront OBJ text, one object per piece (see :func:`pieces_obj`)."""
        return pieces_obj(self.pieces)


def piece_hull(v: np.ndarray) -> trimesh.Trimesh:
    return trimesh.convex.convex_hull(np.asarray(v, dtype=float))


def hull_corners(v: np.ndarray) -> np.ndarray | None:
    """The hull's corner vertices; ``None`` for a flat or degenerate point set."""
    try:
        h = ConvexHull(v)
    except Exception:  # noqa: BLE001 - qhull refuses flat sets with several error types
        return None
    return np.asarray(v)[h.vertices] if h.volume > 0 else None


def pieces_obj(pieces: list[np.ndarray]) -> str:
    """Wavefront OBJ text with one object (a triangulated convex hull) per piece, as engines load compounds."""
    lines: list[str] = []
    base = 1
    for i, v in enumerate(pieces):
        hull = ConvexHull(v)
        lines.append(f"o piece_{i}")
        lines += [f"v {x:.9f} {y:.9f} {z:.9f}" for x, y, z in hull.points]
        lines += [f"f {a + base} {b + base} {c + base}" for a, b, c in hull.simplices]
        base += len(hull.points)
    return "\n".join(lines) + "\n"
