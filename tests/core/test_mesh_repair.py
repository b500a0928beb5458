"""Repair of CAD exports: a few open edges and flipped faces are mended and named; a missing side is refused."""

from __future__ import annotations

import logging

import numpy as np
import pytest
import trimesh

from asmteach.core.corpus import corpus_part, write_cad_stl
from asmteach.core.errors import UserError
from asmteach.core.mesh_repair import holes, repair_mesh
from asmteach.core.models import PartSpec
from asmteach.core.parts import build_part


@pytest.mark.parametrize("name", ["prism_hole_0", "wheel_0", "tube_1", "ff_duck"])
def test_a_cad_stl_with_open_edges_loads_closed_with_its_volume_and_a_warning(tmp_path, caplog, name: str) -> None:
    original = corpus_part(name).mesh
    path = write_cad_stl(original, tmp_path / f"{name}.stl", open_faces=3, seed=2)
    with caplog.at_level(logging.WARNING):
        part = build_part(PartSpec(name=name, mesh=str(path), mesh_units="mm"))
    assert part.mesh.is_watertight
    assert part.mesh.volume == pytest.approx(original.volume, rel=1e-4)
    assert any("filled" in r.getMessage() and "open edges" in r.getMessage() for r in caplog.records)


def test_two_missing_faces_across_a_fold_come_back_as_they_were() -> None:
    # a box without the two triangles that meet along one of its edges (a side's and the top's): the four-edge
    # loop closes by either diagonal, and trimesh's filler takes the one that cuts the corner off (area 26, volume
    # 5 of a 1 x 2 x 3 box); the fill that adds the least surface restores the box
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    keep = np.ones(len(box.faces), bool)
    keep[[1, 3]] = False
    assert abs(float(np.dot(*box.face_normals[[1, 3]]))) < 0.5  # the two faces lie on different sides
    opened = trimesh.Trimesh(box.vertices, box.faces[keep], process=False)
    cut = opened.copy()
    trimesh.repair.fill_holes(cut)
    assert cut.is_watertight and abs(cut.volume) == pytest.approx(5.0)  # the corner cut off
    mended, notes = repair_mesh(opened)
    assert mended.is_watertight
    assert mended.volume == pytest.approx(6.0) and mended.area == pytest.approx(22.0)
    assert any("less added surface" in n for n in notes)


def test_flipped_faces_are_rewound_and_an_inverted_shell_turned_outward() -> None:
    box = trimesh.creation.box(extents=(0.04, 0.03, 0.02))
    flipped = box.faces.copy()
    flipped[:3] = flipped[:3, ::-1]
    fixed, notes = repair_mesh(trimesh.Trimesh(box.vertices, flipped, process=False))
    assert fixed.is_watertight and fixed.volume == pytest.approx(box.volume)
    assert any("re-wound" in n for n in notes)
    inside_out, notes = repair_mesh(trimesh.Trimesh(box.vertices, box.faces[:, ::-1], process=False))
    assert inside_out.volume == pytest.approx(box.volume)
    assert any("outward" in n for n in notes)


def test_a_closed_mesh_is_left_alone() -> None:
    box = trimesh.creation.box(extents=(0.04, 0.03, 0.02))
    fixed, notes = repair_mesh(box)
    assert notes == [] and np.allclose(fixed.vertices[fixed.faces], box.vertices[box.faces])


def test_a_missing_side_is_refused_with_where_the_hole_is() -> None:
    box = trimesh.creation.box(extents=(0.05, 0.04, 0.03)).subdivide().subdivide()
    half = trimesh.Trimesh(box.vertices, box.faces[box.triangles_center[:, 0] < 0.0])
    assert len(holes(half)) == 1
    with pytest.raises(UserError, match=r"half\.stl: .*too much to fill.*around \(0, "):
        repair_mesh(half, name="half.stl")


def test_an_open_sheet_is_refused() -> None:
    grid = trimesh.creation.box(extents=(0.05, 0.05, 0.001)).subdivide()
    sheet = trimesh.Trimesh(grid.vertices, grid.faces[grid.face_normals[:, 2] > 0.9])
    with pytest.raises(UserError, match=r"sheet\.stl"):
        repair_mesh(sheet, name="sheet.stl")
