"""The planner's fast paths against the library routines they replace: qhull hull, components, symmetry tests."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from asmteach.core.models import Placement
from asmteach.core.rests.facets import _components, convex_hull, cross, is_closed
from asmteach.core.rests.placements import plan_placements
from asmteach.core.symmetry.finder import SymmetryFinder, _within


def _blind_hole_block(extents: tuple[float, float, float], radius: float, depth: float, axis: int) -> trimesh.Trimesh:
    """A box with a centred blind cylindrical hole entering from the +``axis`` face."""
    box = trimesh.creation.box(extents=extents)
    hole = trimesh.creation.cylinder(radius=radius, height=2 * depth, sections=32)
    up = np.zeros(3)
    up[axis] = 1.0
    T = trimesh.geometry.align_vectors([0.0, 0.0, 1.0], up)
    T[:3, 3] = up * extents[axis] / 2.0
    hole.apply_transform(T)
    return box.difference(hole, engine="manifold")


def test_hull_matches_trimesh_and_is_consistently_wound() -> None:
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(300, 3)) * [0.03, 0.02, 0.01]
    hull = convex_hull(pts)
    ref = trimesh.convex.convex_hull(pts)
    assert hull.volume == pytest.approx(ref.volume, rel=1e-9)
    assert np.allclose(np.sort(hull.vertices, axis=0), np.sort(np.asarray(ref.vertices), axis=0))
    # Outward normals: every vertex lies on the inner side of every face plane.
    offsets = np.einsum("ij,ij->i", hull.normals, hull.vertices[hull.faces[:, 0]])
    assert np.max(hull.vertices @ hull.normals.T - offsets) < 1e-12
    tri = hull.vertices[hull.faces]
    c = cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(np.einsum("ij,ij->i", c, hull.normals) > 0.0)
    # The neighbour across directed edge a -> b holds the edge b -> a.
    for f in range(len(hull.faces)):
        for k in range(3):
            a, b = hull.faces[f, k], hull.faces[f, (k + 1) % 3]
            g = hull.faces[hull.neighbors[f, k]]
            assert any(g[j] == b and g[(j + 1) % 3] == a for j in range(3))
    assert hull.mesh.is_watertight and hull.mesh.is_winding_consistent
    assert np.allclose(hull.center_mass, ref.center_mass, atol=1e-12)


def test_box_hull_keeps_coplanar_triangles_exactly_coplanar() -> None:
    hull = convex_hull(trimesh.creation.box(extents=(0.1, 0.04, 0.02)))
    assert len(np.unique(np.round(hull.normals, 12), axis=0)) == 6


def test_cross_and_is_closed_agree_with_numpy_and_trimesh() -> None:
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    assert np.allclose(cross(a, b), np.cross(a, b), atol=1e-15)
    box = trimesh.creation.box()
    assert is_closed(box.faces) and box.is_watertight
    assert not is_closed(box.faces[:-1]) and not trimesh.Trimesh(box.vertices, box.faces[:-1]).is_watertight


def test_components_match_scipy() -> None:
    rng = np.random.default_rng(2)
    for n, m in [(1, 0), (10, 0), (50, 30), (200, 180), (300, 600)]:
        a, b = rng.integers(0, n, m), rng.integers(0, n, m)
        count, labels = _components(n, a, b)
        ref_count, ref = connected_components(coo_matrix((np.ones(m), (a, b)), shape=(n, n)), directed=False)
        assert count == ref_count
        # Same partition: labels correspond one to one.
        pairs = np.unique(np.column_stack([labels, ref]), axis=0)
        assert len(pairs) == count


def test_within_matches_trimesh_closest_point() -> None:
    rng = np.random.default_rng(3)
    tri = rng.normal(size=(400, 3, 3))
    n = cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    pts = rng.normal(size=(400, 3))
    d = np.linalg.norm(trimesh.triangles.closest_point(tri, pts) - pts, axis=1)
    for tol in (0.2, 0.5, 1.0):
        assert np.array_equal(_within(pts, tri, n, tol), d <= tol)


def test_symmetry_of_blind_hole_blocks() -> None:
    # 80 x 60 block with a centred hole from the top: C2 about z, nothing about x or y.
    block = _blind_hole_block((0.08, 0.06, 0.04), 0.01, 0.02, axis=2)
    com = block.center_mass
    finder = SymmetryFinder(block, block.convex_hull.vertices, com)
    assert finder.order(np.array([0.0, 0.0, 1.0])) == 2
    assert finder.order(np.array([1.0, 0.0, 0.0])) == 1
    # A 60 mm cube with a hole entering along x: C4 about x (32 hole sections are 4-fold).
    cube = _blind_hole_block((0.06, 0.06, 0.06), 0.01, 0.02, axis=0)
    finder = SymmetryFinder(cube, cube.convex_hull.vertices, cube.center_mass)
    assert finder.order(np.array([1.0, 0.0, 0.0])) == 4
    assert finder.order(np.array([0.0, 0.0, 1.0])) == 1


def test_symmetry_survives_an_asymmetric_tessellation() -> None:
    # A square prism whose faces are split along different diagonals: no rotation maps the
    # faces onto faces, but the surface is C4 about z (the exact surface test decides).
    # Subdividing adds midpoints on the diagonals, which a quarter turn moves off every vertex.
    sub = trimesh.creation.box(extents=(0.04, 0.04, 0.02)).subdivide()
    rng = np.random.default_rng(4)
    order = rng.permutation(len(sub.faces))
    sub = trimesh.Trimesh(sub.vertices, sub.faces[order], process=False)
    finder = SymmetryFinder(sub, sub.convex_hull.vertices, sub.center_mass)
    assert finder.order(np.array([0.0, 0.0, 1.0])) == 4
    assert finder.order(np.array([1.0, 0.0, 0.0])) == 2
    # Off-centre COM: no symmetry about an axis through it.
    finder = SymmetryFinder(sub, sub.convex_hull.vertices, sub.center_mass + np.array([0.003, 0.0, 0.0]))
    assert finder.order(np.array([0.0, 0.0, 1.0])) == 1


def test_placements_are_valid_models() -> None:
    res = plan_placements(_blind_hole_block((0.08, 0.06, 0.04), 0.01, 0.02, axis=2))
    assert len(res.placements) == 6
    for p in res.placements:
        again = Placement.model_validate(p.model_dump())
        assert np.allclose(again.T_table_part, p.T_table_part)
        assert again.support_polygon.shape == p.support_polygon.shape
