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


def test_triangle_distance_matches_a_dense_sampling_of_the_triangle() -> None:
    from asmteach.core.convex_pieces.measure import triangle_distance

    rng = np.random.default_rng(3)
    a, b, c = (rng.normal(size=(200, 3)) for _ in range(3))
    b[:50] = a[:50] + np.array([1.0, 0.0, 0.0]) * rng.uniform(0.001, 0.01, (50, 1))  # long thin triangles
    p = rng.normal(size=(200, 3))
    got = triangle_distance(p, a, b, c)
    uv = rng.uniform(size=(4000, 2))
    uv = np.where(uv.sum(axis=1, keepdims=True) > 1, 1 - uv, uv)
    for i in range(200):
        pts = a[i] + uv[:, :1] * (b[i] - a[i]) + uv[:, 1:] * (c[i] - a[i])
        sampled = np.linalg.norm(pts - p[i], axis=1).min()
        assert sampled - 0.1 <= got[i] <= sampled + 1e-12  # the samples lie a few hundredths apart


def test_a_point_on_a_plate_hole_wall_triangle_is_on_it() -> None:
    """The case trimesh 5.2 answered with 0.118 mm (millimetres here, as the part read)."""
    from asmteach.core.convex_pieces.measure import triangle_distance

    tri = np.array([[25.7882, -19.3654, 1.3273], [25.2258, -19.3930, -1.3273], [25.7882, -19.3654, -1.3273]])
    n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    n /= np.linalg.norm(n)
    p = tri.mean(axis=0) + np.array([0.0, 0.0, -0.3]) + 1e-7 * n
    d = triangle_distance(p[None], tri[None, 0], tri[None, 1], tri[None, 2])
    assert d[0] == pytest.approx(1e-7, abs=1e-9)
