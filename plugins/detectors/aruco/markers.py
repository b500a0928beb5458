"""Marker dictionaries and the object points of a part's markers (part frame, metres)."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from asmteach.core.errors import UserError
from asmteach.core.models import MarkerSpec, PartSpec

__all__ = ["MarkerRef", "corner_offsets", "get_dictionary", "marker_bits", "marker_corners_part", "marker_table"]


def get_dictionary(name: str) -> cv2.aruco.Dictionary:
    """OpenCV predefined dictionary ``name`` (e.g. ``"DICT_4X4_50"``); :class:`UserError` if unknown."""
    code = getattr(cv2.aruco, name, None) if name.startswith("DICT_") else None
    if not isinstance(code, int):
        known = sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_") and n.upper() == n)
        raise UserError(f"unknown ArUco dictionary {name!r}; use one of OpenCV's: {', '.join(known)}")
    return cv2.aruco.getPredefinedDictionary(code)


def corner_offsets(size: float) -> np.ndarray:
    """``(4, 3)`` corners of a marker of side ``size`` (metres) in its own frame, OpenCV's order."""
    h = 0.5 * size
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def marker_corners_part(marker: MarkerSpec) -> np.ndarray:
    """``(4, 3)`` corners of ``marker`` in the part frame (metres), OpenCV's corner order."""
    c = corner_offsets(marker.size)
    T = marker.T_part_marker
    return c @ T[:3, :3].T + T[:3, 3]


def marker_bits(marker: MarkerSpec) -> np.ndarray:
    """``(n+2, n+2) bool`` cell grid of the marker including its black border; True = black.

    Row 0 is the marker's top row (its +y side), column 0 its left (-x) side.
    """
    dictionary = get_dictionary(marker.dictionary)
    n = dictionary.markerSize
    if marker.id >= dictionary.bytesList.shape[0]:
        raise UserError(
            f"marker id {marker.id} does not exist in {marker.dictionary} "
            f"({dictionary.bytesList.shape[0]} ids); use a larger dictionary"
        )
    # One pixel per cell: generateImageMarker draws the exact cell grid.
    img = cv2.aruco.generateImageMarker(dictionary, marker.id, n + 2, borderBits=1)
    return img < 128


@dataclass(frozen=True)
class MarkerRef:
    """Where a detected marker id belongs: part role (``"A"``/``"B"``) and its spec."""

    role: str
    part: str
    spec: MarkerSpec


def marker_table(part_a: PartSpec, part_b: PartSpec) -> dict[tuple[str, int], MarkerRef]:
    """``(dictionary, id) -> MarkerRef`` for both parts; :class:`UserError` on a shared id or bad dictionary."""
    table: dict[tuple[str, int], MarkerRef] = {}
    for role, part in (("A", part_a), ("B", part_b)):
        if not part.markers:
            raise UserError(f"part {part.name!r} has no markers; the ArUco teacher needs at least one per part")
        for m in part.markers:
            get_dictionary(m.dictionary)
            key = (m.dictionary, m.id)
            if key in table:
                other = table[key].part
                raise UserError(
                    f"marker id {m.id} ({m.dictionary}) is used on both {other!r} and {part.name!r}; "
                    "give each marker of a structure its own id"
                )
            table[key] = MarkerRef(role=role, part=part.name, spec=m)
    return table
