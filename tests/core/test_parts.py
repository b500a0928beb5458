from pathlib import Path

import numpy as np
import pytest
import trimesh

from asmteach.core.errors import UserError
from asmteach.core.models import PartSpec
from asmteach.core.parts import build_part, load_structure

REPO = Path(__file__).resolve().parents[2]
STRUCTURES = sorted((REPO / "configs/parts").rglob("*.yaml"))


def test_library_has_two_sets_of_five():
    names = {p.parent.name for p in STRUCTURES}
    assert names == {"set1", "set2"}
    assert sum(p.parent.name == "set1" for p in STRUCTURES) == 5
    assert sum(p.parent.name == "set2" for p in STRUCTURES) == 5


@pytest.mark.parametrize("path", STRUCTURES, ids=lambda p: p.stem)
def test_structure_parts_are_closed_and_do_not_interpenetrate(path):
    task = load_structure(path)
    a, b = build_part(task.part_a), build_part(task.part_b)
    for part in (a, b):
        assert part.mesh.is_watertight
        assert 0.03 <= part.mesh.extents.max() <= 0.1 + 1e-6, "parts are 30-100 mm"
        assert 1 <= len(part.spec.markers) <= 3
        assert part.mass == pytest.approx(part.spec.density * part.mesh.volume)
    b_in_a = b.mesh.copy()
    b_in_a.apply_transform(task.T_A_B)
    overlap = trimesh.boolean.intersection([a.mesh, b_in_a], engine="manifold")
    assert overlap.volume < 1e-9, "B at T_A_B must not penetrate A"
    # B retracted along -v_a by 50 mm is clear of A (the insertion is feasible).
    b_in_a.apply_translation(-0.05 * task.v_a)
    assert trimesh.boolean.intersection([a.mesh, b_in_a], engine="manifold").volume < 1e-12


def test_mesh_in_millimetres_is_refused(tmp_path):
    box = trimesh.creation.box(extents=[60, 40, 30])
    path = tmp_path / "block.stl"
    box.export(path)
    spec = PartSpec(name="b", mesh=str(path))
    with pytest.raises(UserError, match="millimetres"):
        build_part(spec)
    ok = build_part(PartSpec(name="b", mesh=str(path), mesh_units="mm"))
    np.testing.assert_allclose(ok.mesh.extents, [0.06, 0.04, 0.03])


def test_center_of_mass_outside_hull_is_refused():
    spec = load_structure(REPO / "configs/parts/set1/stacked_blocks.yaml").part_a.model_copy(
        update={"center_of_mass": np.array([0.5, 0.0, 0.0])}
    )
    with pytest.raises(UserError, match="outside the part's convex hull"):
        build_part(spec)


def test_missing_mesh_file(tmp_path):
    with pytest.raises(UserError, match="does not exist"):
        build_part(PartSpec(name="x", mesh=str(tmp_path / "nope.stl")))


def test_load_parts_from_structure_part_and_mesh(tmp_path):
    from asmteach.core.parts import load_parts

    structure = REPO / "configs/parts/set1/peg_in_hole.yaml"
    assert [p.name for p in load_parts(structure)] == ["holed_block", "round_peg"]
    assert [p.name for p in load_parts(structure, select="b")] == ["round_peg"]
    assert [p.name for p in load_parts(structure, select="holed_block")] == ["holed_block"]
    with pytest.raises(UserError, match="not a part of"):
        load_parts(structure, select="c")
    mesh = tmp_path / "block.stl"
    trimesh.creation.box(extents=[60, 40, 30]).export(mesh)
    assert load_parts(mesh, units="mm")[0].mesh.extents.max() == pytest.approx(0.06)
    text = tmp_path / "notes.txt"
    text.write_text("x")
    with pytest.raises(UserError, match="nor a part/structure YAML"):
        load_parts(text)
