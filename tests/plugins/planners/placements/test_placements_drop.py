"""Placements on any mesh (issue 22): the facet merge tolerances, rolling rests, and the PyBullet drop test as judge."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from asmteach.core.rests.facets import MERGE_DIST_REL, convex_hull, support_facets
from asmteach.core.rests.placements import PlacementResult, plan_placements
from asmteach.core.rests.stability import evaluate_direction
from asmteach.plugins.planners.placements.drop_test import down_normal, drop_test


def _normals(res: PlacementResult) -> np.ndarray:
    return np.array([down_normal(p.T_table_part) for p in res.placements]).reshape(-1, 3)


def _judge(mesh: trimesh.Trimesh, drops: int = 12, seed: int = 0) -> tuple[PlacementResult, object]:
    res = plan_placements(mesh)
    refused = np.array([r.normal for r in res.rejected]).reshape(-1, 3)
    rep = drop_test(
        mesh, _normals(res), res.center_of_mass, refused_normals=refused, drops=drops, seed=seed, directions=4
    )
    return res, rep


def _rough(mesh: trimesh.Trimesh, max_edge: float, noise: float, seed: int) -> trimesh.Trimesh:
    """``mesh`` cut into triangles of at most ``max_edge`` m with every vertex moved by up to ``noise`` m."""
    v, f = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge)
    rng = np.random.default_rng(seed)
    return trimesh.Trimesh(v + rng.uniform(-noise, noise, v.shape), f)


def test_long_hex_rod_keeps_its_sides_when_faces_are_not_exactly_coplanar() -> None:
    # The case: lying on a side, d/h = tan(30 deg) = 0.58, yet a micrometre of unevenness
    # used to split the side into faces none of which held the COM, and the side was refused.
    rod = _rough(trimesh.creation.cylinder(radius=0.003, height=0.2, sections=6), 0.01, 1e-6, seed=1)
    res = plan_placements(rod)
    sides = [p for p in res.placements if abs(down_normal(p.T_table_part)[2]) < 0.05]
    assert len(sides) == 6
    assert all(p.margin == pytest.approx(np.tan(np.radians(30.0)), abs=0.02) for p in sides)
    assert len(res.placements) == 6  # the ends: d/h = 0.0026 / 0.1, refused


def test_merge_tolerance_is_distance_then_angle() -> None:
    box = trimesh.creation.box(extents=(0.2, 0.02, 0.006))
    delta = MERGE_DIST_REL * 0.2
    # Unevenness within the distance tolerance: six facets, as the exact box.
    inside = support_facets(convex_hull(_rough(box, 0.004, 0.2 * delta, seed=2)))
    assert inside.count == 6
    # A tessellated curve (5.6 degrees between strips, far above 1 degree and 1e-4 of the size) is not merged.
    cyl = support_facets(convex_hull(trimesh.creation.cylinder(radius=0.02, height=0.05, sections=64)))
    assert cyl.count == 66


def test_rolling_rests_of_a_cylinder_and_the_tall_post_still_refused() -> None:
    lying = plan_placements(trimesh.creation.cylinder(radius=0.01, height=0.1, sections=64))
    side = [i for i, p in enumerate(lying.placements) if abs(down_normal(p.T_table_part)[2]) < 1e-6]
    assert len(side) == 64  # every strip: d/h = 0.049 across it, but the strips are one neutral family
    assert all(lying.stability.rolls[lying.facet_of_placement[i]] for i in side)
    assert len({int(lying.stability.basin[lying.facet_of_placement[i]]) for i in side}) == 1  # one family
    # Measured to the end caps instead: d/h = 0.05 / 0.01 (COM height 0.01 * cos(pi / 64)).
    assert lying.placements[side[0]].margin == pytest.approx(0.05 / (0.01 * np.cos(np.pi / 64)), rel=1e-6)
    post = plan_placements(trimesh.creation.cylinder(radius=0.004, height=0.1, sections=64))
    ends = [p for p in post.placements if abs(down_normal(p.T_table_part)[2]) > 0.99]
    assert ends == []  # standing on an end: d/h = 0.08, steep edges, refused as before
    off = plan_placements(trimesh.creation.cylinder(radius=0.01, height=0.1, sections=64), roll_angle_deg=0.0)
    assert len(off.placements) == 2  # rolling rests switched off: only the ends (d/h = 0.2)


@pytest.mark.parametrize(
    "shape",
    ["long_rod", "thin_plate", "tube", "prism_with_hole", "free_form"],
)
def test_planner_agrees_with_the_drop_test(shape: str) -> None:
    if shape == "long_rod":
        mesh = _rough(trimesh.creation.box(extents=(0.15, 0.012, 0.008)), 0.01, 1e-6, seed=3)
    elif shape == "thin_plate":
        mesh = trimesh.creation.box(extents=(0.08, 0.06, 0.003))
    elif shape == "tube":
        mesh = trimesh.creation.annulus(r_min=0.008, r_max=0.012, height=0.08, sections=36)
    elif shape == "prism_with_hole":
        hole = trimesh.creation.cylinder(radius=0.008, height=0.05, sections=32)
        mesh = trimesh.creation.box(extents=(0.05, 0.04, 0.02)).difference(hole, engine="manifold")
    else:  # a lumpy egg: a smooth doubly curved hull with an off-centre COM
        mesh = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
        v = mesh.vertices * [0.04, 0.025, 0.015]
        v[:, 0] += 0.004 * (v[:, 0] / 0.04) ** 2  # fatter at one end
        mesh = trimesh.Trimesh(v, mesh.faces)
    res, rep = _judge(mesh)
    assert rep.unsettled <= 1
    assert rep.found >= 2
    assert rep.missed == 0, f"{shape}: rests not reported {rep.rests[rep.rest_match < 0].round(3).tolist()}"
    assert rep.fragile == 0
    assert rep.spurious == 0, f"{shape}: placements that toppled {np.flatnonzero(~rep.stays & ~rep.rolled)}"
    assert rep.matched == rep.found
    if shape == "tube":
        assert len(res.placements) == 38  # 36 strips on its side (d/h = tan 5 deg = 0.087 across one), 2 ends
    if shape == "free_form":
        assert np.any(np.abs(_normals(res)[:, 2]) > 0.95)  # resting on its flattest side


def test_drop_test_finds_a_missing_placement_and_a_spurious_one() -> None:
    # The judge can fail: hide one side of a square bar and claim a rest on its end, where d/h = 0.05: it
    # stands only while balanced, and released tilted by 4.6 degrees (more than atan 0.05 = 2.9) it falls over.
    box = trimesh.creation.box(extents=(0.2, 0.01, 0.01))
    claimed = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])  # +z side hidden
    rep = drop_test(box, claimed, drops=12, seed=0, directions=4)
    hidden = np.array([0.0, 0.0, 1.0])
    assert any(m == -1 and n @ hidden > 0.99 for n, m in zip(rep.rests, rep.rest_match, strict=True))
    assert rep.missed >= 1
    assert rep.stays[:3].all() and not rep.stays[3] and rep.spurious == 1


def test_every_facet_passing_the_rule_is_reported_and_only_curved_rests_below_it() -> None:
    # The rule against a brute force over hull face planes (independent contact test), on random
    # polytopes and on a part whose faces are uneven by half the merge tolerance.
    rng = np.random.default_rng(5)
    meshes = [trimesh.convex.convex_hull(rng.normal(size=(30, 3)) * [0.04, 0.02, 0.01]) for _ in range(6)]
    meshes.append(_rough(trimesh.creation.box(extents=(0.12, 0.03, 0.02)), 0.01, 0.5 * MERGE_DIST_REL * 0.12, 6))
    for mesh in meshes:
        res = plan_placements(mesh)
        hv, com = res.convex.vertices, res.center_of_mass
        tol = 1.01 * MERGE_DIST_REL * float(np.ptp(hv, axis=0).max())
        ours = _normals(res)
        for n in res.convex.normals:
            if evaluate_direction(hv, com, n, tol=tol).margin >= 0.1 + 1e-6:
                assert np.max(ours @ n) > np.cos(np.radians(1.0)), "a facet with d/h >= 0.1 is missing"
        for c, n in zip(res.facet_of_placement, ours, strict=True):
            plain = evaluate_direction(hv, com, n, tol=max(tol, 1.01 * float(res.facets.depth[c]))).margin
            assert plain >= 0.1 - 1e-6 or res.stability.rolls[c], f"d/h {plain:.3f} reported off a curve"


def test_d_peg_rests_on_its_lowest_strip_only() -> None:
    # A round peg with a flat: its COM moves away from the flat, so on its round side it rolls down to
    # the strips opposite the flat (two, tied at the bottom); the strips above them are sinks of the
    # 64-gon with d/h of a few hundredths that a tilt of 6.9 degrees knocks the part out of.
    cut = trimesh.creation.box(extents=(0.01, 0.03, 0.07))
    cut.apply_translation([0.012, 0.0, 0.0])
    peg = trimesh.creation.cylinder(radius=0.01, height=0.06, sections=64).difference(cut, engine="manifold")
    res, rep = _judge(peg, drops=12)
    side = _normals(res)[np.abs(_normals(res)[:, 2]) < 1e-6]
    assert len(side) == 3  # the two lowest strips and the flat
    assert np.sum(side[:, 0] < -0.99) == 2 and np.sum(side[:, 0] > 0.99) == 1
    assert all("rolls down" in r.reason for r in res.rejected)
    assert rep.missed == 0 and rep.spurious == 0
    assert rep.fragile == rep.below_margin  # every rest the drops found off the placements: a refused strip
