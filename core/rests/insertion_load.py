"""Does a part at rest on the table stay put while another is pushed into it?

B's insertion pushes A along the insertion direction: with B's seat friction while B slides in freely, and
with up to the guarded insertion's force limit when B meets resistance (the rim of a hole, a tight slot:
:class:`~asmteach.core.arm.insertion_records.InsertionSettings.force_limit_n`, the most it pushes before it backs
off). Straight down, that force presses A onto the table; sideways, it drags A across it (a T-slider pushed
along its slot took the block 9.4 mm with it) or tips it over an edge of its footprint. Quasi-static rigid
body, Coulomb friction:

- slides when the horizontal push exceeds ``mu * (m g + F_down)`` (``mu``: table-part friction);
- tips when the push's moment about an edge of the support polygon (the convex hull of A's vertices on the
  table) exceeds the weight's moment about it; a push that presses down helps.

:func:`insertion_stability` answers both for one push; :func:`seat_friction_n` gives the friction a B
sliding on its seat drags A with. Units: metres, newtons, kilograms, newton-metres. Frames: world (the table
top is ``z = table_height``, gravity along ``-z``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from asmteach.core.geometry import transform_points
from asmteach.core.interfaces import PartModel

__all__ = [
    "GRAVITY",
    "PART_FRICTION",
    "TABLE_FRICTION",
    "InsertionStability",
    "insertion_stability",
    "seat_friction_n",
    "support_polygon",
]

GRAVITY = 9.81
"""m/s^2, along world -z."""

TABLE_FRICTION = 0.8
"""Coulomb friction between a part and the table: the simulated world's table (0.8) times a part's (1.0);
PyBullet multiplies the two bodies' coefficients."""

PART_FRICTION = 1.0
"""Coulomb friction between two parts in the simulated world (1.0 x 1.0)."""

SUPPORT_BAND = 0.001
"""Metres: A's vertices this close to its lowest point carry it (the support polygon's corners)."""


@dataclass(frozen=True)
class InsertionStability:
    """What a push along ``direction`` (unit, world) of ``force_n`` newtons does to a part at rest.

    ``slide_margin_n``: friction left after the horizontal push (``mu (m g + F_down) - F_h``; negative:
    it slides). ``tip_margin_nm``: the weight's restoring moment less the push's overturning moment about the
    worst edge of the support polygon (negative: it tips). ``resists_n``: the largest push along ``direction``
    at the same point that neither slides nor tips it (``inf``: any). ``holds``: it neither slides nor tips."""

    force_n: float
    direction: np.ndarray
    slide_margin_n: float
    tip_margin_nm: float
    resists_n: float
    mass_kg: float
    friction: float

    @property
    def slides(self) -> bool:
        return bool(self.slide_margin_n < 0.0)

    @property
    def tips(self) -> bool:
        return bool(self.tip_margin_nm < 0.0)

    @property
    def holds(self) -> bool:
        return not (self.slides or self.tips)

    def summary(self) -> str:
        """One line for a report: what the push does and by how much."""
        what = "slides" if self.slides else "tips" if self.tips else "stays"
        most = "any push" if not np.isfinite(self.resists_n) else f"{self.resists_n:.1f} N"
        return (
            f"{what} under {self.force_n:.1f} N along ({', '.join(f'{v:+.2f}' for v in self.direction)}): "
            f"friction margin {self.slide_margin_n:+.2f} N, tipping margin {1000.0 * self.tip_margin_nm:+.1f} N mm; "
            f"it resists {most}"
        )

    def as_dict(self) -> dict[str, object]:
        return {
            "force_n": round(self.force_n, 2),
            "direction": [round(float(v), 4) for v in self.direction],
            "slides": self.slides,
            "tips": self.tips,
            "holds": self.holds,
            "slide_margin_n": round(float(self.slide_margin_n), 3),
            "tip_margin_nmm": round(1000.0 * float(self.tip_margin_nm), 2),
            "resists_n": round(float(self.resists_n), 2) if np.isfinite(self.resists_n) else None,
            "mass_kg": round(float(self.mass_kg), 4),
            "friction": float(self.friction),
        }


def support_polygon(part: PartModel, T_world_part: np.ndarray, band: float = SUPPORT_BAND) -> np.ndarray:
    """(k, 2) world x, y of the convex hull (counter-clockwise) of the part's vertices within ``band`` metres of
    its lowest point at ``T_world_part``: where it stands on the table."""
    v = transform_points(np.asarray(T_world_part, float), np.asarray(part.mesh.vertices, float))
    low = v[v[:, 2] <= v[:, 2].min() + band, :2]
    try:
        hull = ConvexHull(low)
    except (QhullError, ValueError):  # fewer than three points or all on a line: an edge or a point
        return low[:0] if len(low) == 0 else low[[int(np.argmin(low[:, 0])), int(np.argmax(low[:, 0]))]]
    return low[hull.vertices]  # scipy orders a 2-D hull counter-clockwise


def seat_friction_n(mass_b: float, friction: float = PART_FRICTION) -> float:
    """Newtons a B of ``mass_b`` kilograms sliding on its seat in A drags A with (its weight on the seat)."""
    return friction * mass_b * GRAVITY


def insertion_stability(
    part: PartModel,
    T_world_part: np.ndarray,
    direction: np.ndarray,
    force_n: float,
    point_world: np.ndarray,
    *,
    friction: float = TABLE_FRICTION,
) -> InsertionStability:
    """Whether ``part`` resting on the table at ``T_world_part`` (metres) stays put when pushed with ``force_n``
    newtons along unit ``direction`` (world) at ``point_world`` (metres, where B bears on it); see the module doc.

    A part standing on an edge or a point (no support polygon) has no restoring moment: any push across it tips it.
    """
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    T = np.asarray(T_world_part, float)
    m = float(part.mass)
    f = float(force_n)
    weight = m * GRAVITY
    com = transform_points(T, np.asarray(part.center_of_mass, float)[None])[0]
    p = np.asarray(point_world, float)
    z_table = float(transform_points(T, np.asarray(part.mesh.vertices, float))[:, 2].min())

    # Both margins are affine in the push's size f: margin(f) = at_zero - f * per_newton (per edge for tipping).
    slide0 = friction * weight
    slide_per_n = float(np.hypot(d[0], d[1])) - friction * (max(0.0, -d[2]) - max(0.0, d[2]))
    tip0, tip_per_n = _tip_moments(support_polygon(part, T), z_table, com, weight, p, d)
    margins = [(slide0, slide_per_n), *zip(tip0, tip_per_n, strict=True)]
    limits = [r / k for r, k in margins if k > 0.0]
    return InsertionStability(
        force_n=float(force_n),
        direction=d,
        slide_margin_n=float(slide0 - f * slide_per_n),
        tip_margin_nm=float(np.min(tip0 - f * tip_per_n)),
        resists_n=float(max(0.0, min(limits))) if limits else float("inf"),
        mass_kg=m,
        friction=float(friction),
    )


def _tip_moments(
    poly: np.ndarray, z: float, com: np.ndarray, weight: float, p: np.ndarray, d: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per edge of ``poly`` (world x, y at height ``z``): the weight's restoring moment about it (N m, at ``com``)
    and the overturning moment per newton of push along ``d`` at ``p`` (m). A part on an edge or a point (fewer
    than three corners) restores nothing about a line through its support."""
    if len(poly) < 3:
        lever = max(0.0, float(p[2] - z)) * float(np.hypot(d[0], d[1]))
        return np.zeros(1), np.array([lever])
    g = np.array([0.0, 0.0, -weight])
    restore, per_n = [], []
    for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        e = np.array([a[0], a[1], z])
        # counter-clockwise edge a -> b: outward normal u x z; tipping over it is a turn about u itself
        u = np.append(b - a, 0.0)
        u /= np.linalg.norm(u)
        restore.append(-float(np.cross(com - e, g) @ u))
        per_n.append(float(np.cross(p - e, d) @ u))
    return np.asarray(restore), np.asarray(per_n)
