"""The fidelity measure on shapes whose answer is known: a cube split in two, a half missing, a half grown."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from asmteach.core.convex_pieces import fidelity

_EDGE = 0.02
"""Metres: the cube's edge."""


def _box(lo: tuple[float, float, float], hi: tuple[float, float, float]) -> np.ndarray:
    """The 8 corners of an axis-aligned box (metres)."""
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], float)


def _cube() -> trimesh.Trimesh:
    return trimesh.creation.box(extents=[_EDGE] * 3)  # centred on the origin


_H = 0.5 * _EDGE
_LEFT = _box((-_H, -_H, -_H), (0.0, _H, _H))
_RIGHT = _box((0.0, -_H, -_H), (_H, _H, _H))


def test_a_cube_split_in_two_is_exact_both_ways() -> None:
    h, p, v, u = fidelity([_LEFT, _RIGHT], _cube(), samples=4000)
    assert h < 1e-9 and p < 1e-9 and u < 1e-9 and v < 1e-9


def test_a_missing_half_is_uncovered_by_the_distance_to_the_other() -> None:
    h, p, v, u = fidelity([_LEFT], _cube(), samples=4000)
    # the right half's far face is one half-edge (10 mm) from the left half; nothing protrudes
    assert p < 1e-9
    assert u == pytest.approx(_H, abs=3e-4)
    assert h == u and v == pytest.approx(0.5, abs=1e-6)


def test_a_missing_inner_piece_is_found_inside_the_material() -> None:
    # a 10 mm cube at the centre of a 20 mm cube, surrounded by six slabs that cover the whole surface
    c = 0.5 * _H
    slabs = [
        _box((-_H, -_H, -_H), (-c, _H, _H)),
        _box((c, -_H, -_H), (_H, _H, _H)),
        _box((-c, -_H, -_H), (c, -c, _H)),
        _box((-c, c, -_H), (c, _H, _H)),
        _box((-c, -c, -_H), (c, c, -c)),
        _box((-c, -c, c), (c, c, _H)),
    ]
    _h, p, v, u = fidelity(slabs, _cube(), samples=4000)
    assert p < 1e-9 and v == pytest.approx(0.125, abs=1e-6)
    # the hole's centre is 5 mm from every slab; interior samples come within a millimetre of it
    assert 0.004 < u <= c + 1e-9


def test_a_half_grown_by_half_a_millimetre_protrudes_by_it() -> None:
    grown = _RIGHT.copy()
    grown[grown[:, 2] > 0, 2] += 5e-4  # its top face raised 0.5 mm above the cube's
    h, p, _v, u = fidelity([_LEFT, grown], _cube(), samples=4000)
    assert p == pytest.approx(5e-4, abs=1e-7)
    assert u < 1e-9 and h == p
