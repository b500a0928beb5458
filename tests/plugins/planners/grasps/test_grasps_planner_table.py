"""Grasps of low parts lying on a table: TCP set-backs, approaches straight down, the spread of the kept set.

Fixtures are made in code: box parts and the test hand of ``conftest.py`` (30 mm pads centred on the TCP,
fingertips 15 mm past it). A bar 20 mm tall lying flat is the case that motivated set-backs: with the pads
centred on the contacts, a side grasp from above keeps the fingertips out of the table only for contacts
in the top 5 mm of the sides.
"""

from __future__ import annotations

import itertools

import numpy as np
import open3d as o3d
import pytest

from asmteach.core import geometry
from asmteach.core.hand_geometry import MeshCollider, hand_boxes, pad_grid
from asmteach.core.interfaces import PartModel
from asmteach.core.models import Grasp, HandSpec, PartSpec, Primitive, SolidSpec
from asmteach.core.parts import build_part
from asmteach.core.rests.placements import compute_placements
from asmteach.plugins.planners.grasps.filtering import filter_grasps_at_pose
from asmteach.plugins.planners.grasps.planner import AntipodalGraspPlanner
from asmteach.plugins.planners.grasps.selection import (
    bridge_directions,
    resting_directions,
    sphere_directions,
    table_gaps,
)

_DOWN = np.array([0.0, 0.0, -1.0])


@pytest.fixture(scope="module")
def bar(make_box) -> PartModel:
    """60 x 30 x 20 mm, lying flat (bottom face on z = 0 of the part frame)."""
    return make_box([0.060, 0.030, 0.020], name="low_bar")


@pytest.fixture(scope="module")
def bar_grasps(bar: PartModel, hand: HandSpec) -> list[Grasp]:
    return AntipodalGraspPlanner({"cache": False}, seed=5).plan(bar, hand)


def _lowest_z(hand: HandSpec, g: Grasp, T_world_part: np.ndarray) -> float:
    """World z (metres) of the lowest corner of the fully open hand (palm and fingers) at grasp ``g``."""
    T = T_world_part @ g.T_part_tcp
    corners = np.array(list(itertools.product((-0.5, 0.5), repeat=3)))
    low = np.inf
    for b in hand_boxes(hand, hand.max_width):
        pts = (b.center + corners * b.size) @ T[:3, :3].T + T[:3, 3]
        low = min(low, float(pts[:, 2].min()))
    return low


def _from_above_and_clear(hand: HandSpec, grasps: list[Grasp], T_world_part: np.ndarray) -> list[Grasp]:
    """Grasps approaching within 15 deg of straight down whose open hand stays above the table (z = 0)."""
    out = []
    for g in grasps:
        T = T_world_part @ g.T_part_tcp
        if T[:3, 2] @ _DOWN >= np.cos(np.radians(15.0)) and _lowest_z(hand, g, T_world_part) > 0.0:
            out.append(g)
    return out


def test_low_bar_on_table_has_grasps_from_above_clear_of_it(bar, hand) -> None:
    planner = AntipodalGraspPlanner({"cache": False}, seed=5)
    grasps = planner.plan(bar, hand)
    assert planner.last_stats["shallow"] > 0
    clear = _from_above_and_clear(hand, grasps, np.eye(4))
    assert len(clear) >= 5
    for g in clear:
        # The fingertips reach 15 mm past the TCP, so the TCP (the pads' centre) is in the top 5 mm of the
        # bar's sides: far above the side faces' centres, where most contacts are sampled.
        assert g.T_part_tcp[2, 3] > 0.015 - 1e-9
        # ... the contacts' midpoint is the TCP (the Grasp model) and the pads press on the bar's side faces
        np.testing.assert_allclose(g.T_part_tcp[:3, 3], 0.5 * (g.p0 + g.p1), atol=1e-12)
        axis = int(np.argmax(np.abs(g.R[:, 1])))
        assert axis in (0, 1)
        half = [0.030, 0.015][axis]
        assert abs(abs(g.p0[axis]) - half) < 1e-6 and abs(abs(g.p1[axis]) - half) < 1e-6


def test_set_back_pads_press_the_faces(bar, hand, bar_grasps) -> None:
    """Every kept grasp, set back or not (the soft-pad contact model, checked by distances instead of rays):
    a contact lies under each pad at least ``edge_margin`` inside its fingertip edge, and no part material
    stands more than the pads' compliance in front of either pad plane."""
    s = AntipodalGraspPlanner.Settings()
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(bar.mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor(np.asarray(bar.mesh.faces, dtype=np.uint32)),
    )
    grid = pad_grid(hand, 9, 13, inset=0.0005)
    reach = 0.5 * hand.pad_size[1] - s.edge_margin
    for g in bar_grasps:
        x, y, z = g.R[:, 0], g.R[:, 1], g.R[:, 2]
        for p, out in ((g.p0, -y), (g.p1, y)):
            # the contact: on the pad's centre line, from the pad centre up to `reach` toward the fingertip
            line = np.asarray([p + t * z for t in np.linspace(0.0, reach, 50)], dtype=np.float32)
            assert scene.compute_distance(o3d.core.Tensor(line)).numpy().min() < 2e-4, g.id
            # pad points moved back by the compliance (plus the 1.25 mm gap grid's reach) are outside the part
            pts = np.asarray([p + a * x + c * z + (s.compliance + 1e-4) * out for a, c in grid], dtype=np.float32)
            sd = scene.compute_signed_distance(o3d.core.Tensor(pts)).numpy()
            assert sd.min() > -1e-5, g.id


def test_low_bar_feasible_from_above_at_a_pose(bar, hand, bar_grasps, point_arm, table) -> None:
    """With the filter of a part pose (hand swept 3 cm back along its approach): usable grasps from above."""
    T_world_part = geometry.from_rpy(0.0, 0.0, 0.4, t=[0.2, -0.1, 0.0])
    verdicts = filter_grasps_at_pose(bar_grasps, T_world_part, point_arm, [table], approach_sweep=0.03)
    ok = [v for v in verdicts if v.feasible and v.T_world_tcp[:3, 2] @ _DOWN > 0.95]
    assert ok
    assert all(_lowest_z(hand, v.grasp, T_world_part) > 0.0 for v in ok)


def test_approaches_straight_down_in_every_resting_pose(bar, bar_grasps) -> None:
    down = resting_directions(bar)
    # a box rests on each of its six faces
    assert len(down) == 6
    np.testing.assert_allclose(np.sort(np.abs(down).sum(axis=1)), np.ones(6), atol=1e-9)
    approach = np.array([g.R[:, 2] for g in bar_grasps])
    for u in down:
        ok = approach @ u > 1.0 - 1e-9
        if abs(u[0]) > 0.5:  # resting on a 30 x 20 end: the only pair across is the 60 mm length, within the stroke
            assert ok.any()
        else:
            assert ok.sum() >= 3, u


def test_kept_set_spread_over_resting_poses(block, hand) -> None:
    """A small budget still covers every resting pose of a block with grasps approaching from above."""
    grasps = AntipodalGraspPlanner({"cache": False, "max_grasps": 60}, seed=2).plan(block, hand)
    assert len(grasps) == 60
    scores = [g.score for g in grasps]
    assert scores == sorted(scores, reverse=True)
    approach = np.array([g.R[:, 2] for g in grasps])
    for u in resting_directions(block):
        assert np.count_nonzero(approach @ u >= 0.9) >= 3, u


def test_seeded_with_set_backs(bar, hand, bar_grasps) -> None:
    again = AntipodalGraspPlanner({"cache": False}, seed=5).plan(bar, hand)
    assert [g.model_dump_json() for g in again] == [g.model_dump_json() for g in bar_grasps]


def test_table_gaps_of_a_grasp_from_above(bar, hand) -> None:
    """TCP 25 mm up over a 20 mm bar, straight down: the fingertips (15 mm past the TCP) are 10 mm up."""
    R = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # x -> part y, jaw along part x, down
    gaps = table_gaps(bar, hand, R[None], np.array([[0.0, 0.0, 0.025]]), np.array([0.064]), np.array([_DOWN]))
    assert gaps.shape == (1, 1)
    assert gaps[0, 0] == pytest.approx(0.010, abs=1e-9)
    # resting on its top face instead (the part's +z into the table), the hand is 45 mm into the table
    flipped = table_gaps(bar, hand, R[None], np.array([[0.0, 0.0, 0.025]]), np.array([0.064]), -np.array([_DOWN]))
    assert flipped[0, 0] < -0.04


def test_sphere_directions_even_and_deterministic() -> None:
    d = sphere_directions(32)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    np.testing.assert_array_equal(d, sphere_directions(32))
    cos = d @ d.T - 2.0 * np.eye(32)
    # no two directions closer than 25 deg; every direction of a fine grid within 30 deg of one of them
    assert cos.max() < np.cos(np.radians(25.0))
    probe = sphere_directions(2000)
    assert (probe @ d.T).max(axis=1).min() > np.cos(np.radians(30.0))


def test_fully_open_hand_clear_of_the_part(make_box, hand) -> None:
    """A U channel: the robot opens the hand completely before each approach, so no kept grasp may straddle
    a wall with one finger in the 25 mm channel (fully open, that finger would swing into the other wall)."""
    channel = make_box(
        [0.080, 0.065, 0.040],
        name="u_channel",
        subtract=[Primitive(shape="box", size=[0.090, 0.025, 0.025], pose={"xyz": [0, 0, 0.0275]})],
    )
    full = AntipodalGraspPlanner({"cache": False}, seed=1).plan(channel, hand)
    shaped = AntipodalGraspPlanner({"cache": False, "approach_opening": "pre-shaped"}, seed=1).plan(channel, hand)
    collider = MeshCollider({"part": (channel.mesh, np.eye(4))})

    def open_hits(g: Grasp) -> bool:
        return collider.collides(hand_boxes(hand, hand.max_width, sweep=0.03), g.T_part_tcp)

    assert not any(open_hits(g) for g in full)
    # the pre-shaped hand may go into the channel: some of those grasps would hit the part fully open
    assert any(open_hits(g) for g in shaped)


def test_bridge_directions_of_a_box(bar) -> None:
    """A box rests on six faces: each of the 12 pairs 90 deg apart gets its bisector, opposite faces none."""
    down = resting_directions(bar)
    dirs, pairs = bridge_directions(down)
    assert dirs.shape == (12, 3) and pairs.shape == (12, 2)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-12)
    for d, (i, j) in zip(dirs, pairs, strict=True):
        assert d @ down[i] == pytest.approx(np.sqrt(0.5)) and d @ down[j] == pytest.approx(np.sqrt(0.5))
    assert bridge_directions(down, max_angle_deg=60.0)[0].shape == (0, 3)


def _turning_grasps(hand: HandSpec, part: PartModel, grasps: list[Grasp], pose_a, pose_b) -> list[Grasp]:
    """Grasps approaching within 60 deg of straight down with the open hand above the table in both poses."""
    out = []
    for g in grasps:
        ok = True
        for p in (pose_a, pose_b):
            T = p.T_table_part @ g.T_part_tcp
            ok &= bool(T[:3, 2] @ _DOWN >= 0.5) and _lowest_z(hand, g, p.T_table_part) > 0.0
        if ok:
            out.append(g)
    return out


def test_headed_peg_on_its_head_can_be_turned_over(hand) -> None:
    """A peg standing on its 40 mm head: from above only its shank is free of the table, and grasps steep
    there lie horizontal once the peg lies on its side. Bridge grasps (from above in both) turn it over;
    without them (``bridge_poses: 0``) only a few of the orientation grid's do."""
    head = Primitive(shape="box", size=[0.040, 0.040, 0.016], pose={"xyz": [0, 0, 0.026]})
    shank = Primitive(shape="box", size=[0.018, 0.018, 0.018], pose={"xyz": [0, 0, 0.009]})
    peg = build_part(PartSpec(name="headed_peg", solid=SolidSpec(add=[head, shank])))
    placements = compute_placements(peg)
    on_head = next(p for p in placements if p.T_table_part[:3, :3].T @ _DOWN @ [0, 0, 1] > 0.99)
    on_side = [p for p in placements if abs(p.T_table_part[:3, :3].T @ _DOWN @ [0, 0, 1]) < 0.01]
    assert on_side

    def turning(settings: dict) -> int:
        grasps = AntipodalGraspPlanner({"cache": False, **settings}, seed=3).plan(peg, hand)
        return sum(len(_turning_grasps(hand, peg, grasps, on_head, p)) for p in on_side)

    with_bridges, without = turning({}), turning({"bridge_poses": 0})
    assert with_bridges >= 12  # 19 when written
    assert with_bridges > 3 * without  # 3 without: the orientation grid's few at 45 deg
