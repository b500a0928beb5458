"""The antipodal planner on boxes made in code: geometry of the grasps, pads, collisions, cache, bad input."""

from __future__ import annotations

import itertools

import numpy as np
import open3d as o3d
import pytest
import trimesh

from asmteach.core.errors import UserError
from asmteach.core.hand_geometry import hand_boxes
from asmteach.core.interfaces import PartModel
from asmteach.core.models import Primitive
from asmteach.plugins.planners.grasps.antipodal import antipodal_mask, friction_half_angle, wrench_space_quality
from asmteach.plugins.planners.grasps.planner import AntipodalGraspPlanner


def _planner(tmp_path, **settings) -> AntipodalGraspPlanner:
    return AntipodalGraspPlanner({"cache_dir": str(tmp_path / "cache"), **settings}, seed=3)


@pytest.fixture(scope="module")
def block_grasps(block, hand, tmp_path_factory):
    planner = AntipodalGraspPlanner({"cache": False}, seed=3)
    return planner.plan(block, hand), planner.last_stats


def test_grasp_frames_and_contacts(block: PartModel, block_grasps) -> None:
    grasps, _ = block_grasps
    assert [g.id for g in grasps] == list(range(len(grasps)))
    scores = [g.score for g in grasps]
    assert scores == sorted(scores, reverse=True)
    ext = np.array([0.040, 0.060, 0.030])
    for g in grasps:
        R = g.R
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-9)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-9)
        np.testing.assert_allclose(R[:, 1], (g.p1 - g.p0) / np.linalg.norm(g.p1 - g.p0), atol=1e-6)
        assert g.width == pytest.approx(np.linalg.norm(g.p1 - g.p0), abs=1e-9)
        # a box is grasped across one of its three widths, contacts on opposite faces
        assert np.min(np.abs(ext - g.width)) < 1e-5
        for p in (g.p0, g.p1):
            assert np.min(np.abs(np.abs(p - [0, 0, 0.015]) - ext / 2)) < 1e-5
        np.testing.assert_allclose(g.T_part_tcp[:3, 3], 0.5 * (g.p0 + g.p1), atol=1e-12)


def test_all_three_widths_and_many_distinct(block_grasps) -> None:
    grasps, stats = block_grasps
    widths = {round(g.width, 4) for g in grasps}
    assert widths == {0.03, 0.04, 0.06}
    assert len(grasps) >= 40
    assert stats["kept"] == len(grasps)


def test_no_near_duplicates(block_grasps) -> None:
    grasps, _ = block_grasps
    cos15 = np.cos(np.radians(15.0))
    flip = np.diag([-1.0, -1.0, 1.0])
    for a, b in itertools.combinations(grasps, 2):
        if np.linalg.norm(a.T_part_tcp[:3, 3] - b.T_part_tcp[:3, 3]) > 0.005:
            continue
        c_same = (np.trace(a.R.T @ b.R) - 1) / 2
        c_swap = (np.trace(a.R.T @ b.R @ flip) - 1) / 2
        assert max(c_same, c_swap) <= cos15 + 1e-9


def test_hand_clear_of_part_and_pads_on_surface(block: PartModel, hand, block_grasps) -> None:
    """Checked independently of fcl: points filling the hand boxes are outside the part (Open3D signed distance)."""
    grasps, _ = block_grasps
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(block.mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor(np.asarray(block.mesh.faces, dtype=np.uint32)),
    )
    u = np.stack(np.meshgrid(*[np.linspace(-0.5, 0.5, 6)] * 3, indexing="ij"), -1).reshape(-1, 3)
    for g in grasps[:80]:
        T = g.T_part_tcp
        pts = []
        for b in hand_boxes(hand, g.width + 0.001):
            pts.append((b.center + u * b.size) @ T[:3, :3].T + T[:3, 3])
        sd = scene.compute_signed_distance(o3d.core.Tensor(np.concatenate(pts).astype(np.float32))).numpy()
        assert sd.min() > -1e-5, f"grasp {g.id}: hand box inside the part by {-sd.min() * 1000:.2f} mm"
        # the pad centre (contact) is on the surface, and at least half of each pad lies on the face
        x, z = T[:3, 0], T[:3, 2]
        for p in (g.p0, g.p1):
            grid = [p + a * x + c * z for a in np.linspace(-0.0095, 0.0095, 5) for c in np.linspace(-0.0145, 0.0145, 7)]
            d = scene.compute_distance(o3d.core.Tensor(np.asarray(grid, dtype=np.float32))).numpy()
            assert (d < 1e-4).mean() >= 0.5 - 1e-9


def test_full_pad_support_is_stricter(block, hand, tmp_path) -> None:
    loose = _planner(tmp_path, cache=False).plan(block, hand)
    strict = _planner(tmp_path, cache=False, pad_min_support=1.0).plan(block, hand)
    assert 0 < len(strict) < len(loose)
    # fully supported: the whole 20 x 30 mm pad lies inside the contact face
    ext = np.array([0.040, 0.060, 0.030])
    for g in strict:
        axis = int(np.argmax(np.abs(g.R[:, 1])))
        for p in (g.p0, g.p1):
            for a, c in itertools.product((-0.0095, 0.0095), (-0.0145, 0.0145)):
                q = p + a * g.R[:, 0] + c * g.R[:, 2] - [0, 0, 0.015]
                others = [i for i in range(3) if i != axis]
                # within the contact model's gap grid resolution (pad points read the nearest of a 1.25 mm grid)
                assert np.all(np.abs(q[others]) <= ext[others] / 2 + 0.0009)


def test_seeded_and_cached(block, hand, tmp_path) -> None:
    p1 = _planner(tmp_path)
    first = p1.plan(block, hand)
    assert p1.last_stats["cache_hit"] is False
    assert list((tmp_path / "cache").glob("block-*.json"))
    p2 = _planner(tmp_path)
    again = p2.plan(block, hand)
    assert p2.last_stats["cache_hit"] is True
    assert [g.model_dump_json() for g in again] == [g.model_dump_json() for g in first]
    fresh = _planner(tmp_path, cache=False).plan(block, hand)
    assert [g.model_dump_json() for g in fresh] == [g.model_dump_json() for g in first]
    other = AntipodalGraspPlanner({"cache_dir": str(tmp_path / "cache"), "mu": 0.5}, seed=3)
    assert other.cache_key(block, hand) != p1.cache_key(block, hand)


def test_groove_under_pad_and_collision(make_box, hand, tmp_path) -> None:
    """A deep slot splits the top face: grasps across the slot walls must not put the fingers in the material."""
    part = make_box(
        [0.050, 0.030, 0.040],
        name="slotted",
        subtract=[Primitive(shape="box", size=[0.012, 0.040, 0.030], pose={"xyz": [0, 0, 0.030]})],
    )
    grasps = _planner(tmp_path, cache=False).plan(part, hand)
    assert len(grasps) > 0
    for g in grasps:
        # contacts never on the 12 mm slot walls: a 10 mm finger would have to enter the 12 mm slot with
        # its 20 mm pad, which cannot fit; across the slot the width would be the 19 mm wall
        walls = np.abs(np.abs([g.p0[0], g.p1[0]]) - 0.006) < 1e-6
        assert not walls.all()


def test_friction_cone_and_force_closure() -> None:
    rng = np.random.default_rng(0)
    p0 = np.zeros((400, 3))
    p1 = np.tile([0.0, 0.04, 0.0], (400, 1))
    tilt = np.radians(rng.uniform(0, 30, (400, 2)))
    az = rng.uniform(0, 2 * np.pi, (400, 2))

    def normal(base, t, a):
        perp = np.stack([np.cos(a), np.zeros_like(a), np.sin(a)], 1)
        return np.cos(t)[:, None] * base + np.sin(t)[:, None] * perp

    n0 = normal(np.array([0.0, -1.0, 0.0]), tilt[:, 0], az[:, 0])
    n1 = normal(np.array([0.0, 1.0, 0.0]), tilt[:, 1], az[:, 1])
    ok = antipodal_mask(p0, n0, p1, n1, 0.3)
    cone = friction_half_angle(0.3)
    assert cone == pytest.approx(np.radians(16.699), abs=1e-4)
    np.testing.assert_array_equal(ok, np.all(tilt <= cone, axis=1))
    # The wrench-space test (soft fingers, linearised cones) agrees away from the cone boundary.
    for i in range(0, 400, 7):
        margin = np.degrees(np.max(tilt[i]) - cone)
        if abs(margin) < 2.5:
            continue
        q = wrench_space_quality(np.stack([p0[i], p1[i]]), np.stack([n0[i], n1[i]]), 0.3, torsion=0.003, edges=16)
        assert (q > 0) == bool(ok[i]), (i, margin, q)
    # point contacts (no torsion) can never resist twisting about the grasp axis
    assert wrench_space_quality(np.stack([p0[0], p1[0]]), np.array([[0, -1.0, 0], [0, 1.0, 0]]), 0.3) == 0.0


def _mesh_part(mesh: trimesh.Trimesh, name: str) -> PartModel:
    from asmteach.core.models import PartSpec

    spec = PartSpec(name=name, mesh=f"{name}.stl")
    return PartModel(spec=spec, mesh=mesh, mass=0.1, center_of_mass=np.asarray(mesh.centroid))


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: trimesh.creation.box([0.12, 0.10, 0.09]), "no graspable width"),
        (lambda: trimesh.creation.box([0.05, 0.05, 0.0008]), "thin shell"),
        (lambda: trimesh.creation.box([40.0, 40.0, 30.0]), "millimetres"),
        (lambda: _open_box(), "open shell"),
        (lambda: _inverted_box(), "point inward"),
        (lambda: _flipped_faces_box(), "degenerate"),
    ],
)
def test_bad_input(make, message, hand, tmp_path) -> None:
    with pytest.raises(UserError, match=message):
        _planner(tmp_path, cache=False).plan(_mesh_part(make(), "bad"), hand)


def _open_box() -> trimesh.Trimesh:
    m = trimesh.creation.box([0.04, 0.04, 0.04])
    m.update_faces(np.arange(len(m.faces)) > 1)
    return m


def _inverted_box() -> trimesh.Trimesh:
    m = trimesh.creation.box([0.04, 0.04, 0.04])
    m.invert()
    return m


def _flipped_faces_box() -> trimesh.Trimesh:
    m = trimesh.creation.box([0.04, 0.04, 0.04])
    faces = m.faces.copy()
    faces[:3] = faces[:3, ::-1]
    return trimesh.Trimesh(m.vertices, faces, process=False)
