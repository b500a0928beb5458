"""Refining protruding pieces (core.convex_pieces.refine): cut where a piece bridges a concavity, keep coverage."""

from __future__ import annotations

import numpy as np
import trimesh

from asmteach.core.convex_pieces import fidelity
from asmteach.core.convex_pieces.refine import refine_protruding


def _l_block() -> trimesh.Trimesh:
    """An L: a 40 x 20 x 10 mm bar with a 10 x 20 x 20 mm post on one end (metres)."""
    bar = trimesh.creation.box(extents=[0.04, 0.02, 0.01])
    post = trimesh.creation.box(extents=[0.01, 0.02, 0.02])
    post.apply_translation([0.015, 0.0, 0.015])
    return bar.union(post, engine="manifold")


def test_the_hull_of_an_l_is_cut_into_pieces_that_neither_protrude_nor_uncover() -> None:
    mesh = _l_block()
    hull = [np.asarray(mesh.convex_hull.vertices)]
    _, p0, _, _ = fidelity(hull, mesh, samples=3000)
    assert p0 > 0.005  # the hull fills the L's inner corner
    pieces = refine_protruding(hull, mesh, tolerance=1e-4, max_pieces=8)
    assert 2 <= len(pieces) <= 8
    _, p, v, u = fidelity(pieces, mesh, samples=3000)
    assert p < 1e-4 and u < 1e-6 and v < 1e-4


def test_the_piece_bound_is_kept_and_pieces_within_tolerance_are_untouched() -> None:
    mesh = _l_block()
    hull = [np.asarray(mesh.convex_hull.vertices)]
    assert len(refine_protruding(hull, mesh, tolerance=1e-4, max_pieces=1)) == 1
    assert len(refine_protruding(hull, mesh, tolerance=0.02, max_pieces=8)) == 1
