"""Exact convex decomposition of parametric solids (core.convex_pieces.solid_pieces)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import Delaunay

from asmteach.core.convex_pieces import (
    DecompositionSettings,
    decompose,
    pieces_obj,
    primitive_halfspaces,
    solid_pieces,
    split_convex,
)
from asmteach.core.models import Primitive, SolidSpec


def _holed_block() -> SolidSpec:
    return SolidSpec(
        add=[Primitive(shape="box", size=[0.08, 0.06, 0.04], pose={"xyz": [0, 0, 0.02]})],
        subtract=[Primitive(shape="cylinder", radius=0.0105, height=0.05, pose={"xyz": [0, 0, 0.04]})],
    )


def _inside_any(pieces: list[np.ndarray], pts: np.ndarray) -> np.ndarray:
    inside = np.zeros(len(pts), bool)
    for v in pieces:
        inside |= Delaunay(v).find_simplex(pts) >= 0
    return inside


def test_box_halfspaces_contain_exactly_the_box() -> None:
    hs = primitive_halfspaces(Primitive(shape="box", size=[0.02, 0.04, 0.06], pose={"xyz": [0.1, 0, 0]}))
    inside = np.array([0.1 + 0.0099, 0.0199, 0.0299])
    outside = np.array([0.1 + 0.0101, 0.0, 0.0])
    assert np.all(hs[:, :3] @ inside + hs[:, 3] <= 0)
    assert np.any(hs[:, :3] @ outside + hs[:, 3] > 0)


def test_holed_block_pieces_are_the_solid_and_keep_the_hole_open() -> None:
    pieces = solid_pieces(_holed_block())
    assert len(pieces) > 4
    rng = np.random.default_rng(0)
    pts = rng.uniform([-0.045, -0.035, -0.005], [0.045, 0.035, 0.045], (20000, 3))
    r = np.hypot(pts[:, 0], pts[:, 1])
    in_box = np.all(np.abs(pts - [0, 0, 0.02]) <= [0.04, 0.03, 0.02], axis=1)
    # the 64-gon hole lies between the apothem and the radius; keep samples clear of that band
    in_hole = (r < 0.0105 * np.cos(np.pi / 64)) & (pts[:, 2] > 0.015)
    clear = np.abs(r - 0.0105) > 2e-4
    solid = in_box & ~in_hole
    got = _inside_any(pieces, pts)
    assert np.array_equal(got[clear], solid[clear])
    # a 0.5 mm-clearance peg fits: points on a 10 mm circle inside the hole are free
    t = np.linspace(0, 2 * np.pi, 90)
    ring = np.column_stack([0.010 * np.cos(t), 0.010 * np.sin(t), np.full(90, 0.03)])
    assert not _inside_any(pieces, ring).any()


def test_cut_missing_a_piece_leaves_it_whole() -> None:
    spec = SolidSpec(
        add=[Primitive(shape="box", size=[0.02, 0.02, 0.02])],
        subtract=[Primitive(shape="box", size=[0.01, 0.01, 0.01], pose={"xyz": [0.5, 0, 0]})],
    )
    pieces = solid_pieces(spec)
    assert len(pieces) == 1 and len(pieces[0]) == 8


@pytest.mark.parametrize("n_pieces", [1, 3])
def test_obj_text_has_one_object_per_piece(n_pieces: int) -> None:
    cube = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    text = pieces_obj([cube + i for i in range(n_pieces)])
    assert text.count("\no ") + text.startswith("o ") == n_pieces
    assert sum(line.startswith("v ") for line in text.splitlines()) == 8 * n_pieces
    faces = [list(map(int, line.split()[1:])) for line in text.splitlines() if line.startswith("f ")]
    assert len(faces) == 12 * n_pieces and max(max(f) for f in faces) == 8 * n_pieces


def test_plane_split_of_a_stepped_block_is_two_exact_boxes() -> None:
    """(Moved from the grasps plugin, whose own plane split this module replaced.)"""
    import trimesh

    block = trimesh.creation.box(extents=[0.08, 0.04, 0.04])
    block.apply_translation([0, 0, 0.02])
    step = trimesh.creation.box(extents=[0.041, 0.05, 0.021])
    step.apply_translation([0.0205, 0, 0.0405])
    mesh = block.difference(step, engine="manifold")
    pieces, approx = split_convex(mesh)
    assert approx == 0 and len(pieces) == 2
    assert sum(p.volume for p in pieces) == pytest.approx(mesh.volume, rel=1e-6)
    for p in pieces:  # convex but for the 0.2 um slab a cut leaves beside a face (split_convex)
        assert p.convex_hull.volume == pytest.approx(p.volume, rel=1e-5)


def test_a_solid_part_takes_the_exact_route_and_a_convex_mesh_is_one_piece() -> None:
    import trimesh

    from asmteach.core.interfaces import PartModel
    from asmteach.core.models import PartSpec
    from asmteach.core.parts import build_part, mesh_hash

    spec = PartSpec(name="cube", solid=SolidSpec(add=[Primitive(shape="box", size=[0.03, 0.02, 0.01])]))
    solid = build_part(spec)
    d = decompose(solid, DecompositionSettings(samples=2000), cache=False)
    assert d.method == "solid" and len(d.pieces) == 1 and len(d.pieces[0]) == 8
    np.testing.assert_allclose(d.pieces[0].min(axis=0), solid.mesh.bounds[0], atol=1e-9)
    assert d.hausdorff < 1e-6 and d.protrusion < 1e-6 and d.volume_error < 1e-6
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.02)
    ball = PartModel(
        spec=PartSpec(name="ball", mesh="ball.stl"),
        mesh=mesh,
        mass=0.1,
        center_of_mass=np.zeros(3),
        source_hash=mesh_hash(mesh),
    )
    d = decompose(ball, DecompositionSettings(samples=2000), cache=False)
    assert d.method == "convex" and len(d.pieces) == 1 and d.protrusion < 1e-6
