"""Stable placements: analytic boxes, library parts against trimesh, symmetry, bad input."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
import trimesh

from asmteach.core import geometry
from asmteach.core.errors import UserError
from asmteach.core.parts import build_part, load_structure
from asmteach.core.rests.placements import (
    canonical_rotation,
    compute_placements,
    placement_result,
    plan_placements,
    resting_poses,
)
from asmteach.core.rests.stability import evaluate_direction

REPO = Path(__file__).resolve().parents[3]


def _down_normal(T: np.ndarray) -> np.ndarray:
    return T[:3, :3].T @ np.array([0.0, 0.0, -1.0])


def test_box_placements_are_analytic() -> None:
    box = trimesh.creation.box(extents=(0.10, 0.04, 0.02))
    res = plan_placements(box)
    assert len(res.placements) == 6
    # Quasi-static probabilities of a convex body cover the whole sphere of directions.
    assert sum(p.probability for p in res.placements) == pytest.approx(1.0, abs=1e-9)
    by_normal = {tuple(np.round(np.abs(_down_normal(p.T_table_part)), 6)): p for p in res.placements}
    flat = by_normal[(0.0, 0.0, 1.0)]  # resting on the 0.10 x 0.04 face: d = 0.02, h = 0.01
    assert flat.margin == pytest.approx(2.0, rel=1e-9)
    end = by_normal[(1.0, 0.0, 0.0)]  # on the 0.04 x 0.02 end: d = 0.01, h = 0.05
    assert end.margin == pytest.approx(0.2, rel=1e-9)
    for p in res.placements:
        v = trimesh.transform_points(box.vertices, p.T_table_part)
        assert v[:, 2].min() == pytest.approx(0.0, abs=1e-12)
        assert len(p.symmetry_yaws) == 2  # a box is C2 about each face normal
        # canonical yaw: the COM sits above the table origin
        com = p.T_table_part[:3, :3] @ box.center_mass + p.T_table_part[:3, 3]
        assert np.allclose(com[:2], 0.0, atol=1e-12)
    x, y = flat.support_polygon.T
    poly_area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))  # shoelace
    assert poly_area == pytest.approx(0.10 * 0.04, rel=1e-9)


def test_canonical_rotation_puts_normal_down_with_zero_yaw() -> None:
    rng = np.random.default_rng(3)
    for n in [*rng.normal(size=(20, 3)), np.array([1.0, 0, 0]), np.array([-1.0, 0, 0]), np.array([0, 0, 1.0])]:
        n = n / np.linalg.norm(n)
        R = canonical_rotation(n)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.allclose(R @ n, [0.0, 0.0, -1.0], atol=1e-12)
        assert abs(R[1, 0]) < 1e-12  # R = Ry Rx has no yaw: its (1, 0) entry is 0


def test_tall_post_fails_the_margin_and_is_refused() -> None:
    post = trimesh.creation.box(extents=(0.01, 0.01, 0.20))
    res = plan_placements(post, min_margin=0.1)
    normals = [np.abs(_down_normal(p.T_table_part)) for p in res.placements]
    assert not any(np.allclose(n, [0, 0, 1]) for n in normals)  # standing on end: d/h = 0.005 / 0.1 = 0.05
    assert len(res.placements) == 4
    assert any(r.margin == pytest.approx(0.05) for r in res.rejected)
    # With the margin lowered it becomes a placement.
    assert len(plan_placements(post, min_margin=0.04).placements) == 6


def test_cylinder_symmetry_order() -> None:
    cyl = trimesh.creation.cylinder(radius=0.02, height=0.03, sections=64)
    res = plan_placements(cyl)
    orders = sorted(len(p.symmetry_yaws) for p in res.placements)
    # End faces: C64, of which 32 is the largest divisor <= the tested maximum 36.
    assert orders[-2:] == [32, 32]


@pytest.mark.parametrize("structure", sorted((REPO / "configs/parts/set1").glob("*.yaml"))[:3], ids=lambda p: p.stem)
def test_library_parts_agree_with_trimesh(structure: Path) -> None:
    task = load_structure(structure)
    for spec in (task.part_a, task.part_b):
        part = build_part(spec, structure.parent)
        ours = compute_placements(part)
        hull_v = np.asarray(part.mesh.convex_hull.vertices)
        ours_n = np.array([_down_normal(p.T_table_part) for p in ours])
        for p in ours:  # none of ours fails the independent test
            assert evaluate_direction(hull_v, part.center_of_mass, _down_normal(p.T_table_part)).margin >= 0.1 - 1e-9
        T_tm, p_tm = trimesh.poses.compute_stable_poses(part.mesh, center_mass=part.center_of_mass)
        for T, p in zip(T_tm, p_tm, strict=True):
            n = _down_normal(T)
            if p >= 0.05 and evaluate_direction(hull_v, part.center_of_mass, n).margin >= 0.1:
                assert np.max(ours_n @ n) > np.cos(np.radians(1.0)), f"{spec.name}: trimesh pose p={p:.3f} missed"


@pytest.fixture(scope="module")
def l_block():
    """Asymmetric L-shaped block (set 1, l_corner part A)."""
    path = REPO / "configs/parts/set1/l_corner.yaml"
    return build_part(load_structure(path).part_a, path.parent)


def test_cache_serves_the_same_result(l_block) -> None:
    a = placement_result(l_block)
    b = placement_result(l_block)
    assert a is b
    first = compute_placements(l_block)
    first[0].T_table_part[0, 3] = 99.0  # callers get copies; the cache stays intact
    assert compute_placements(l_block)[0].T_table_part[0, 3] != 99.0


def test_com_outside_hull_is_refused() -> None:
    box = trimesh.creation.box(extents=(0.05, 0.05, 0.05))
    with pytest.raises(UserError, match="outside the convex hull"):
        plan_placements(box, np.array([0.1, 0.0, 0.0]))


def test_flat_mesh_is_refused() -> None:
    sheet = trimesh.Trimesh([[0, 0, 0], [0.1, 0, 0], [0.1, 0.1, 0], [0, 0.1, 0]], [[0, 1, 2], [0, 2, 3]])
    with pytest.raises(UserError, match="flat or degenerate"):
        plan_placements(sheet)


def test_open_mesh_uses_hull_and_warns_once(caplog: pytest.LogCaptureFixture) -> None:
    box = trimesh.creation.box(extents=(0.061, 0.043, 0.027))
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-2])
    with caplog.at_level(logging.WARNING):
        a = plan_placements(open_box, name="open box")
        b = plan_placements(open_box, name="open box")
    assert sum("not watertight" in r.getMessage() for r in caplog.records) == 1
    assert len(a.placements) == len(b.placements) == 6
    assert "convex hull used" in a.notes[0]


def test_resting_poses_centre_the_footprint_and_weigh_the_likely_rests() -> None:
    """A 10 x 20 x 40 mm box rests on its six faces; the flat ones are likelier, the probabilities sum to 1."""
    box = trimesh.creation.box(extents=[0.01, 0.02, 0.04])
    box.apply_translation([0.3, -0.2, 0.1])  # the part frame need not be centred
    placements = plan_placements(box, symmetry=False).placements
    Ts, p = resting_poses(placements, box.vertices)
    assert Ts.shape == (len(placements), 4, 4) == (6, 4, 4)
    assert p.sum() == pytest.approx(1.0) and np.all(np.diff(p) <= 1e-12)
    for T in Ts:
        v = geometry.transform_points(T, box.vertices)
        assert v[:, 2].min() == pytest.approx(0.0, abs=1e-12)
        assert np.allclose(0.5 * (v.min(axis=0) + v.max(axis=0))[:2], 0.0, atol=1e-12)
    # lying flat (on a 20 x 40 face, 5 mm up) comes first; standing on a 10 x 20 end is least likely
    first = geometry.transform_points(Ts[0], box.vertices)
    assert first[:, 2].max() == pytest.approx(0.01)
    assert geometry.transform_points(Ts[-1], box.vertices)[:, 2].max() == pytest.approx(0.04)
    few, q = resting_poses(placements, box.vertices, min_probability=0.2)
    assert len(few) == int(np.sum(p >= 0.2)) and q.sum() == pytest.approx(1.0)
    assert len(resting_poses(placements, box.vertices, min_probability=1.0)[0]) == 1  # the likeliest always kept
    empty, none = resting_poses([], box.vertices)
    assert empty.shape == (0, 4, 4) and none.shape == (0,)


def test_resting_poses_are_trimesh_stable_poses_with_trimesh_yaw() -> None:
    """The random start scenes still draw trimesh's rests (see core.scene): the two must stay the same poses."""
    box = trimesh.creation.box(extents=[0.01, 0.02, 0.04])
    Ts, _ = resting_poses(plan_placements(box, symmetry=False).placements, box.vertices)
    T_tm, _ = trimesh.poses.compute_stable_poses(box)
    for T in T_tm:
        v = geometry.transform_points(T, box.vertices)
        c = 0.5 * (v.min(axis=0) + v.max(axis=0))
        T = geometry.compose(geometry.from_rotation(np.eye(3), [-c[0], -c[1], -v[:, 2].min()]), T)
        assert min(np.abs(T - ours).max() for ours in Ts) < 1e-12
