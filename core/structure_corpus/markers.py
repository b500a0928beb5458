"""Where a marker may go on a generated part, its pose there, and the layout drawn for a structure.

A site is a rectangle on a flat outer face (metres, the assembled build
frame); a marker's square plus its one-cell quiet zone stays 1 mm inside it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from asmteach.core import geometry

MARKER_DICTIONARY = "DICT_4X4_50"
DICT_IDS = 50
_MARKER_CELLS = 6  # a 4x4 marker: 4 data cells and a one-cell black border on each side
_QUIET_CELLS = 1.0  # white margin the renderer draws around a marker (render.RenderObject.quiet_zone_cells)
_EDGE_MARGIN = 0.001  # m kept between a marker's quiet zone and the face's edge
_MARKER_MIN = 0.010  # m; smaller squares are too few pixels at the demonstration's 0.45 m
_MARKER_MAX = 0.035
_UP = np.array([0.0, 0.0, 1.0])


def quiet_side(size: float) -> float:
    """Side of a marker's square with its quiet zone, metres."""
    return size * (1.0 + 2.0 * _QUIET_CELLS / _MARKER_CELLS)


# ---------------------------------------------------------------- marker sites
@dataclass(frozen=True)
class MarkerSite:
    """A rectangle on a flat outer face, in the assembled frame (A's build frame), where a marker may go."""

    center: tuple[float, float, float]
    normal: tuple[float, float, float]
    half: tuple[float, float]  # half extents of the rectangle along its two in-plane axes, metres

    def max_marker(self) -> float:
        """Largest marker side (metres) whose quiet zone fits the rectangle with the edge margin."""
        room = 2.0 * (min(self.half) - _EDGE_MARGIN)
        return room / (1.0 + 2.0 * _QUIET_CELLS / _MARKER_CELLS)


def face_site(axis: str, value: float, lo: tuple[float, float], hi: tuple[float, float]) -> MarkerSite:
    """A rectangle on the plane ``<axis> = value`` with outward normal ``sign(axis)`` (metres).

    ``axis`` is one of ``+x -x +y -y +z -z``; ``lo``/``hi`` bound the other two
    coordinates in order (x, y, z without the normal's one).
    """
    k = "xyz".index(axis[1])
    normal = [0.0, 0.0, 0.0]
    normal[k] = 1.0 if axis[0] == "+" else -1.0
    centre = [0.0, 0.0, 0.0]
    centre[k] = value
    for j, i in enumerate(i for i in range(3) if i != k):
        centre[i] = 0.5 * (lo[j] + hi[j])
    return MarkerSite(tuple(centre), tuple(normal), (0.5 * (hi[0] - lo[0]), 0.5 * (hi[1] - lo[1])))


def marker_pose(site: MarkerSite) -> np.ndarray:
    """Marker frame on a site: z out of the face; on a vertical face y up, on a horizontal one x along +x."""
    z = np.asarray(site.normal, float)
    if abs(z[2]) > 0.9:
        x = np.array([1.0, 0.0, 0.0])
        y = np.cross(z, x)
    else:
        y = _UP
        x = np.cross(y, z)
    return geometry.from_rotation(np.column_stack([x, y, z]), site.center)


def pick_layout(
    rng: np.random.Generator, sites_a: list[MarkerSite], sites_b: list[MarkerSite]
) -> tuple[list[tuple[MarkerSite, float]], list[tuple[MarkerSite, float]]]:
    """1-4 sites per part with a marker size each; one A marker and one B marker face within 90 deg."""
    usable_a = [s for s in sites_a if s.max_marker() >= _MARKER_MIN]
    usable_b = [s for s in sites_b if s.max_marker() >= _MARKER_MIN]
    if not usable_a or not usable_b:
        raise RuntimeError("a generated part has no face a marker fits")  # a generator defect
    # First a pair a camera sees together (normals within 90 deg), then the rest of each part's markers.
    pairs = [
        (i, j)
        for i, sa in enumerate(usable_a)
        for j, sb in enumerate(usable_b)
        if float(np.dot(sa.normal, sb.normal)) >= 0.0
    ]
    if not pairs:
        raise RuntimeError("no face of B is seen together with a face of A")  # a generator defect
    first_a, first_b = pairs[int(rng.integers(len(pairs)))]

    def fill(usable: list[MarkerSite], first: int) -> list[MarkerSite]:
        n = min(int(rng.integers(1, 5)), len(usable))
        rest = [i for i in range(len(usable)) if i != first]
        more = [rest[k] for k in rng.choice(len(rest), size=n - 1, replace=False)] if n > 1 else []
        return [usable[i] for i in sorted([first, *more])]

    chosen_a, chosen_b = fill(usable_a, first_a), fill(usable_b, first_b)

    def sized(s: MarkerSite) -> tuple[MarkerSite, float]:
        hi = min(s.max_marker(), _MARKER_MAX)
        # Markers are cut from printed sheets: a size in whole half-millimetres.
        size = np.floor(float(rng.uniform(max(_MARKER_MIN, 0.6 * hi), hi)) * 2000.0) / 2000.0
        return s, float(max(size, _MARKER_MIN))

    return [sized(s) for s in chosen_a], [sized(s) for s in chosen_b]
