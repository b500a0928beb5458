"""Generated structures (issue 23): closed parts, a seat without interpenetration, the drawn clearance, a free
insertion path, visible markers, and mm STL + structure YAML that load back as the same task."""

from __future__ import annotations

import warnings

import fcl
import numpy as np
import pytest
import trimesh

from asmteach.core.models import MarkerSpec
from asmteach.core.parts import build_part, load_structure
from asmteach.core.structure_corpus import (
    STRUCTURE_FAMILIES,
    GeneratedStructure,
    generate_structure,
    marker_problems,
    structure_corpus,
    write_run_config,
    write_structure,
)

SEEDS = (0, 1, 2)
LIFT = 5e-6  # m: B moved this far off its seat (up and back along -v_a), so touching faces do not count as contact


@pytest.fixture(scope="module")
def structures() -> list[GeneratedStructure]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return [generate_structure(f, s) for s in SEEDS for f in STRUCTURE_FAMILIES]


def _bvh(mesh: trimesh.Trimesh) -> fcl.CollisionObject:
    model = fcl.BVHModel()
    model.beginModel(len(mesh.vertices), len(mesh.faces))
    model.addSubModel(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64))
    model.endModel()
    return fcl.CollisionObject(model, fcl.Transform())


class _Pair:
    """A fixed in its frame, B placed by an offset (A's frame, metres) from its seat lifted by LIFT."""

    def __init__(self, gs: GeneratedStructure) -> None:
        self.gs = gs
        self.a, self.b = _bvh(gs.part_a), _bvh(gs.part_b)
        self.off = LIFT * (np.array([0.0, 0.0, 1.0]) - gs.v_a)

    def _place(self, offset: np.ndarray) -> None:
        T = self.gs.T_A_B.copy()
        T[:3, 3] += self.off + offset
        self.b.setTransform(fcl.Transform(T[:3, :3], T[:3, 3]))

    def collides(self, offset: np.ndarray) -> bool:
        self._place(offset)
        return fcl.collide(self.a, self.b, fcl.CollisionRequest(), fcl.CollisionResult()) > 0

    def distance(self, offset: np.ndarray) -> float:
        self._place(offset)
        return float(fcl.distance(self.a, self.b, fcl.DistanceRequest(), fcl.DistanceResult()))


def test_every_family_is_made_closed_in_part_frames_and_sized_for_the_gripper(structures):
    assert {gs.family for gs in structures} == set(STRUCTURE_FAMILIES)
    for gs in structures:
        for mesh in (gs.part_a, gs.part_b):
            assert mesh.is_watertight and mesh.is_volume and mesh.volume > 0, gs.name
            lo, hi = mesh.bounds
            # part frame: bounding-box bottom face centre at the origin
            assert np.allclose([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]], 0.0, atol=1e-9), gs.name
            assert 0.020 <= float(np.max(mesh.extents)) <= 0.120, gs.name
            assert float(np.min(mesh.extents[:2])) <= 0.070, gs.name  # the gripper opens 85 mm
        b = gs.part_b.copy()
        b.apply_transform(gs.T_A_B)
        lo = np.minimum(gs.part_a.bounds[0], b.bounds[0])
        hi = np.maximum(gs.part_a.bounds[1], b.bounds[1])
        assert 0.020 <= float(np.max(hi - lo)) <= 0.120, gs.name
        assert b.bounds[0][2] >= -1e-9, f"{gs.name}: B reaches under the table A stands on"
        assert 0.2e-3 <= gs.clearance <= 1.0e-3
        assert np.isclose(np.linalg.norm(gs.v_a), 1.0)


def test_b_sits_on_its_seat_touching_a_without_interpenetration(structures):
    for gs in structures:
        b = gs.part_b.copy()
        b.apply_transform(gs.T_A_B)
        common = trimesh.boolean.intersection([gs.part_a, b], engine="manifold")
        assert common.volume < 1e-10, f"{gs.name}: {common.volume * 1e9:.3f} mm^3 of B inside A"
        pair = _Pair(gs)
        assert not pair.collides(np.zeros(3)), gs.name
        # Touching: lifted off the seat by LIFT, B is that far from A, no more.
        assert pair.distance(np.zeros(3)) < 3 * LIFT, gs.name


def _play(pair: _Pair, d: np.ndarray, hi: float = 3e-3) -> float:
    """How far B moves along ``d`` from its (lifted) seat before it touches A, by bisection (metres)."""
    lo = 0.0
    assert pair.collides(hi * d), "B moves 3 mm sideways without touching A: nothing holds it"
    for _ in range(16):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if pair.collides(mid * d) else (mid, hi)
    return lo


def test_sideways_play_is_the_drawn_clearance(structures):
    for gs in structures:
        pair = _Pair(gs)
        for axis in gs.play_axes:
            for sign in (1.0, -1.0):
                play = _play(pair, sign * np.asarray(axis))
                assert abs(play - gs.clearance) < 0.05e-3, (
                    f"{gs.name}: play {play * 1e3:.3f} mm along {sign:+.0f}{axis}, drawn {gs.clearance * 1e3:.2f} mm"
                )


def test_engaged_distance_is_the_clearance_where_only_the_sides_are_close(structures):
    # Retracted 3 mm along -v_a, every axial face is >= 3 mm away: the nearest faces are the sides, c apart.
    # (Slides stay on their groove floor as they move; their clearance is measured as play above.)
    for gs in structures:
        if gs.family in ("dovetail_slide", "t_slot_slide"):
            continue
        pair = _Pair(gs)
        dist = pair.distance(-3e-3 * gs.v_a - pair.off)
        assert abs(dist - gs.clearance) < 0.05e-3, f"{gs.name}: {dist * 1e3:.3f} vs {gs.clearance * 1e3:.2f} mm"


def test_b_comes_out_along_minus_v_a_without_touching_a(structures):
    for gs in structures:
        pair = _Pair(gs)
        steps = np.arange(0.0, gs.insertion_depth + 3e-3, 0.5e-3)
        hit = [s for s in steps if pair.collides(-s * gs.v_a)]
        assert not hit, f"{gs.name}: B hits A {hit[0] * 1e3:.1f} mm out along -v_a"
        assert pair.distance(-(gs.insertion_depth + 3e-3) * gs.v_a) > 2e-3, f"{gs.name}: B still engaged"
        assert gs.insertion_depth > 3e-3, gs.name


def test_markers_are_on_visible_outer_faces_with_unique_ids(structures):
    for gs in structures:
        assert marker_problems(gs) == [], gs.name
        assert 1 <= len(gs.markers_a) <= 4 and 1 <= len(gs.markers_b) <= 4
        ids = [m.id for m in gs.markers_a + gs.markers_b]
        assert len(set(ids)) == len(ids)
        for m in gs.markers_a + gs.markers_b:
            assert m.dictionary == "DICT_4X4_50" and 0 <= m.id < 50 and 0.010 <= m.size <= 0.035
        # One A marker and one B marker face within 90 deg: one camera sees both parts' markers.
        na = np.array([m.T_part_marker[:3, 2] for m in gs.markers_a])
        nb = np.array([(gs.T_A_B @ m.T_part_marker)[:3, 2] for m in gs.markers_b])
        assert float(np.max(na @ nb.T)) >= -1e-9, gs.name


def test_a_marker_under_the_other_part_or_off_the_face_is_reported():
    gs = generate_structure("round_peg", 0)
    top = float(gs.part_a.bounds[1][2])
    covered = MarkerSpec(id=49, size=0.01, T_part_marker={"xyz": [0, 0, top], "rpy_deg": [0, 0, 0]})
    floating = MarkerSpec(id=48, size=0.01, T_part_marker={"xyz": [0, 0, top + 0.004], "rpy_deg": [0, 0, 0]})
    bad = GeneratedStructure(**{**gs.__dict__, "markers_a": [covered, floating]})
    problems = marker_problems(bad)
    assert any("49" in p and "covered" in p for p in problems), problems
    assert any("48" in p and "not flat" in p for p in problems), problems


@pytest.mark.parametrize("family", STRUCTURE_FAMILIES)
def test_written_files_load_back_as_the_same_task(family, tmp_path):
    gs = generate_structure(family, 1)
    path = write_structure(gs, tmp_path / gs.name)
    assert (tmp_path / gs.name / "A.stl").is_file() and (tmp_path / gs.name / "B.stl").is_file()
    # millimetres in the file
    raw = trimesh.load(tmp_path / gs.name / "A.stl", force="mesh")
    assert np.allclose(raw.extents, gs.part_a.extents * 1000.0, atol=1e-3)
    assert not raw.is_watertight  # CAD-style open edges, repaired on load
    task = load_structure(path)
    assert np.allclose(task.T_A_B, gs.T_A_B, atol=1e-7)
    assert np.allclose(task.v_a, gs.v_a)
    for spec, mesh, markers in ((task.part_a, gs.part_a, gs.markers_a), (task.part_b, gs.part_b, gs.markers_b)):
        assert spec.mesh_units == "mm"
        part = build_part(spec, path.parent)
        assert part.mesh.is_watertight
        assert np.allclose(part.mesh.bounds, mesh.bounds, atol=1e-6)
        assert part.mesh.volume == pytest.approx(mesh.volume, rel=0.01)
        assert [m.id for m in spec.markers] == [m.id for m in markers]
        for got, want in zip(spec.markers, markers, strict=True):
            assert got.size == pytest.approx(want.size)
            assert np.allclose(got.T_part_marker, want.T_part_marker, atol=1e-7)
    assert "structure: structure.yaml" in write_run_config(gs, path.parent).read_text()


def test_same_seed_writes_the_same_bytes_and_another_seed_other_sizes(tmp_path):
    for family in ("keyed_peg", "side_pin"):
        one = write_structure(generate_structure(family, 3), tmp_path / "one" / family).parent
        two = write_structure(generate_structure(family, 3), tmp_path / "two" / family).parent
        for name in ("A.stl", "B.stl", "structure.yaml"):
            assert (one / name).read_bytes() == (two / name).read_bytes(), name
        other = generate_structure(family, 4)
        assert not np.allclose(other.part_a.extents, generate_structure(family, 3).part_a.extents)


def test_the_corpus_cycles_over_the_families():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        corpus = structure_corpus(seed=5, count=12)
    assert [gs.family for gs in corpus[:10]] == list(STRUCTURE_FAMILIES)
    assert corpus[10].family == STRUCTURE_FAMILIES[0] and corpus[10].name != corpus[0].name
    assert len({gs.name for gs in corpus}) == 12


def test_make_structures_command_writes_a_folder_per_structure(tmp_path, capsys):
    from asmteach.core.cli import main

    assert main(["make-structures", str(tmp_path / "gen"), "--seed", "2", "--count", "2"]) == 0
    folders = sorted(p.name for p in (tmp_path / "gen").iterdir())
    assert folders == ["gen_round_peg_s2_0", "gen_square_peg_s2_0"]
    for name in folders:
        for f in ("A.stl", "B.stl", "structure.yaml", "run.yaml"):
            assert (tmp_path / "gen" / name / f).is_file()
