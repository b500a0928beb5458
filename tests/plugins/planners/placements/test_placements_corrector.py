"""The stable_placements corrector on synthetic rough poses and clouds with known noise."""

from __future__ import annotations

import numpy as np
import pytest

from asmteach.core import geometry
from asmteach.core.errors import UserError
from asmteach.core.interfaces import Corrector
from asmteach.core.models import TablePlane
from asmteach.core.rests.placements import compute_placements
from asmteach.plugins.planners.placements.corrector import StablePlacementCorrector, nearest_placement

H = 0.70  # table height, metres
CAMERA = np.array([0.0, -0.35, H + 0.45])
UP = np.array([0.0, 0.0, 1.0])


def _true_pose(placement, rng: np.random.Generator) -> np.ndarray:
    T = geometry.rot_z(rng.uniform(-np.pi, np.pi)) @ placement.T_table_part
    T[:3, 3] += [rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), H]
    return T


def _yaw_error_deg(T: np.ndarray, T_true: np.ndarray, order: int = 1) -> float:
    M = T[:3, :3] @ T_true[:3, :3].T
    yaw = np.arctan2(M[1, 0], M[0, 0])
    period = 2 * np.pi / order
    return float(np.degrees(abs((yaw + period / 2) % period - period / 2)))


def _check_resting(c, part, placement) -> None:
    T = c.T_world_part
    lowest = geometry.transform_points(T, part.mesh.vertices)[:, 2].min()
    assert abs(lowest - H) < 1e-4  # target: within 0.1 mm (in fact to rounding)
    assert abs(lowest - H) < 1e-9
    up_part = T[:3, :3].T @ UP  # roll and pitch: the table normal seen in the part frame
    assert np.allclose(up_part, placement.T_table_part[:3, :3].T @ UP, atol=1e-12)


def test_is_a_corrector() -> None:
    assert issubclass(StablePlacementCorrector, Corrector)


def test_nearest_placement_is_the_minimum_over_yaw() -> None:
    rng = np.random.default_rng(0)
    Rp = np.stack([geometry.from_rotvec(rng.normal(size=3))[:3, :3] for _ in range(5)])
    R_raw = geometry.from_rotvec(rng.normal(size=3))[:3, :3]
    d, psi = nearest_placement(R_raw, Rp)
    yaws = np.linspace(-np.pi, np.pi, 20001)
    for k in range(5):
        brute = [geometry.rotation_distance(geometry.rot_z(y)[:3, :3] @ Rp[k], R_raw) for y in yaws[::50]]
        assert d[k] <= min(brute) + 1e-9
        assert geometry.rotation_distance(geometry.rot_z(psi[k])[:3, :3] @ Rp[k], R_raw) == pytest.approx(d[k])


def test_snap_without_cloud_rests_exactly_and_keeps_yaw(l_block) -> None:
    placements = compute_placements(l_block)
    corr = StablePlacementCorrector({"refine": False})
    rng = np.random.default_rng(1)
    for trial in range(10):
        placement = placements[trial % len(placements)]
        T_true = _true_pose(placement, rng)
        T_rough = (
            geometry.rot_z(np.radians(3.0))
            @ geometry.from_rotvec(rng.normal(size=3) / np.sqrt(3) * np.radians(6.0))
            @ T_true
        )
        T_rough[:3, 3] += rng.normal(0.0, 0.003, 3)
        c = corr.correct(T_rough, l_block, TablePlane(height=H))
        assert c.placement_id == placement.id
        _check_resting(c, l_block, placement)
        # Without a cloud the yaw is the raw one (3 deg off), up to the tilt noise.
        assert _yaw_error_deg(c.T_world_part, T_true) < 9.0


@pytest.mark.parametrize("name", ["l_block", "t_slot_block", "cube"])
def test_planar_refinement_meets_the_targets(name: str, request: pytest.FixtureRequest, scene) -> None:
    part = request.getfixturevalue(name)
    placements = compute_placements(part)
    corr = StablePlacementCorrector({}, seed=0)
    rng = np.random.default_rng(7)
    for trial in range(4):
        placement = placements[trial % len(placements)]
        T_true = _true_pose(placement, rng)
        cloud = scene.visible_cloud(part.mesh, T_true, CAMERA, noise=0.0005, seed=trial)
        T_rough = scene.perturb(T_true, rng, rot_deg=8.0, yaw_deg=18.0, trans=0.004)
        c = corr.correct(T_rough, part, TablePlane(height=H), cloud)
        assert c.placement_id == placement.id
        assert c.details["icp"]["applied"], c.details["icp"]
        _check_resting(c, part, placement)
        order = len(placement.symmetry_yaws)
        assert _yaw_error_deg(c.T_world_part, T_true, order) <= 2.0
        com_err = geometry.transform_points(c.T_world_part, part.center_of_mass[None]) - geometry.transform_points(
            T_true, part.center_of_mass[None]
        )
        assert np.linalg.norm(com_err[0, :2]) <= 0.0015
        if order == 1:
            assert np.linalg.norm(c.T_world_part[:2, 3] - T_true[:2, 3]) <= 0.0015


def test_symmetric_equivalent_nearest_the_raw_pose(cube, scene) -> None:
    placement = compute_placements(cube)[0]
    T_true = geometry.rot_z(0.3) @ placement.T_table_part
    T_true[:3, 3] += [0.02, 0.01, H]
    rng = np.random.default_rng(3)
    T_rough = scene.perturb(T_true, rng, rot_deg=5.0, yaw_deg=10.0, trans=0.003)
    cloud = scene.visible_cloud(cube.mesh, T_true, CAMERA, seed=3)
    near = StablePlacementCorrector({"symmetry": "nearest_raw"}).correct(T_rough, cube, TablePlane(height=H), cloud)
    canon = StablePlacementCorrector({"symmetry": "canonical"}).correct(T_rough, cube, TablePlane(height=H), cloud)
    # Both are the same geometry (C4), near keeps the raw orientation, canonical a yaw in [-45, 45) deg.
    assert _yaw_error_deg(near.T_world_part, T_true) <= 2.0
    assert _yaw_error_deg(canon.T_world_part, T_true, order=4) <= 2.0
    assert abs(canon.details["yaw_deg"]) <= 45.0 + 1e-9
    assert near.details["symmetry_order"] == 4


def test_table_fitted_from_the_scene(l_block, scene) -> None:
    placement = compute_placements(l_block)[1]
    rng = np.random.default_rng(11)
    T_true = _true_pose(placement, rng)
    part_pts = scene.visible_cloud(l_block.mesh, T_true, CAMERA, seed=11)
    cloud = np.vstack([part_pts, scene.table_cloud(np.zeros(2), 0.25, H)])
    T_rough = scene.perturb(T_true, rng, rot_deg=6.0, yaw_deg=12.0, trans=0.003)
    c = StablePlacementCorrector({}, seed=1).correct(T_rough, l_block, None, cloud)
    assert c.details["table"]["fitted"]
    assert c.details["table"]["height"] == pytest.approx(H, abs=0.001)
    assert np.degrees(np.arccos(np.clip(np.asarray(c.details["table"]["normal"]) @ UP, -1, 1))) < 0.5
    assert abs(geometry.transform_points(c.T_world_part, l_block.mesh.vertices)[:, 2].min() - H) < 0.001
    assert _yaw_error_deg(c.T_world_part, T_true) <= 2.0


def test_paper_mode_rpy_yaw_and_origin_pivot(l_block) -> None:
    placement = compute_placements(l_block)[0]
    T_true = geometry.rot_z(0.5) @ placement.T_table_part
    T_true[:3, 3] += [0.0, 0.0, H]
    T_rough = geometry.from_rpy(0.05, -0.04, 0.0) @ T_true
    c = StablePlacementCorrector({"yaw_from": "rpy", "pivot": "origin", "refine": False}).correct(
        T_rough, l_block, TablePlane(height=H)
    )
    _check_resting(c, l_block, placement)
    assert np.allclose(c.T_world_part[:2, 3], T_rough[:2, 3], atol=1e-12)  # paper: p_c = (p_r.x, p_r.y, .)


def test_no_table_and_no_cloud_is_a_user_error(l_block) -> None:
    with pytest.raises(UserError, match="table plane"):
        StablePlacementCorrector({}).correct(np.eye(4), l_block, None, None)


def test_cloud_of_only_the_part_cannot_fit_a_table(l_block, scene) -> None:
    placement = compute_placements(l_block)[0]
    T_true = _true_pose(placement, np.random.default_rng(2))
    cloud = scene.visible_cloud(l_block.mesh, T_true, CAMERA, seed=2)
    with pytest.raises(UserError, match="no table plane"):
        StablePlacementCorrector({"table": "fit"}).correct(T_true, l_block, TablePlane(height=H), cloud)


def _headed_pin():
    """A pin with a 29.7 mm square head 15.8 mm long and an 11.3 mm shank 31.3 mm long (a generated side_pin's
    B): on its head's edge and its shank's tip it rests with d / h = 0.049, under the 0.1 of a placement."""
    import trimesh

    from asmteach.core.interfaces import PartModel
    from asmteach.core.models import PartSpec

    head = trimesh.creation.box(extents=[0.0297, 0.0297, 0.0158])
    head.apply_translation([0.0, 0.0, 0.0079])
    shank = trimesh.creation.cylinder(radius=0.00565, height=0.0313, sections=48)
    shank.apply_translation([0.0, 0.0, 0.0158 + 0.01565])
    mesh = trimesh.boolean.union([head, shank], engine="manifold")
    return PartModel(PartSpec(name="headed_pin", mesh="pin.stl"), mesh, 0.02, np.asarray(mesh.center_mass))


def test_a_rough_pose_at_a_marginal_rest_is_snapped_there_not_to_a_robust_placement_16_deg_away() -> None:
    from asmteach.core.rests.placements import placement_result

    part = _headed_pin()
    loose = placement_result(part, min_margin=0.01, angle_tol_deg=1.0)
    rest = next(p for p in loose.placements if 0.01 < p.margin < 0.1)  # the tilted rest
    T_true = geometry.rot_z(0.4) @ rest.T_table_part
    T_true[:3, 3] += [0.4, 0.1, H]
    T_rough = T_true @ geometry.from_rpy(np.radians(2.0), np.radians(-2.0), 0.0)  # 3 deg off, as detected
    c = StablePlacementCorrector().correct(T_rough, part, TablePlane(height=H))
    assert c.details["marginal_rest"] is True
    # roll and pitch are the rest's; the yaw is kept from the rough pose (no cloud to refine it here)
    assert np.allclose(c.T_world_part[:3, :3].T @ UP, T_true[:3, :3].T @ UP, atol=1e-9)
    assert np.degrees(geometry.rotation_distance(c.T_world_part, T_true)) < 3.0
    # without the fallback the nearest placement with d / h >= 0.1 is 16 deg away
    far = StablePlacementCorrector({"max_snap_deg": 90.0}).correct(T_rough, part, TablePlane(height=H))
    assert np.degrees(geometry.rotation_distance(far.T_world_part, T_true)) > 10.0
