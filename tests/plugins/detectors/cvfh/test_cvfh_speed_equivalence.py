"""The speed-ups of issue 27 change no result: the pruned ray tree of ``surface_check``, the batched
distance query of the pre-score and its distance-grid bounds give exactly what the unpruned / one-pose-at-a-time /
ray-casting computations give; a verification rejected before its surface check says what it said with it; the
near-twin screen finds the pose the full near-twin pass finds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
from scipy.spatial import cKDTree

from asmteach.core import geometry
from asmteach.core.corpus import corpus_part
from asmteach.core.parts import PartSpec, build_part
from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings
from asmteach.core.perception.registration import (
    ModelCloud,
    RefineSettings,
    _free_space_violation,
    check_surface,
    model_cloud,
    verify,
)
from asmteach.core.perception.surface_check import ray_depths
from asmteach.core.rests.drops import drop_rests
from asmteach.plugins.detectors.cvfh.detector import CvfhIcpDetector
from asmteach.plugins.detectors.cvfh.prescore import SampleIndex, near_shares
from asmteach.plugins.detectors.cvfh.scenes import DEFAULT_EYE, default_camera_pose, place_on_table, render_table_scene


@pytest.fixture(scope="module")
def scene_and_model():  # type: ignore[no-untyped-def]
    """A prism with a hole lying on the table, seen by the scene Kinect; its model cloud."""

    mesh = corpus_part("prism_hole_0").mesh
    T, p = drop_rests(mesh, mesh.center_mass)
    T_true = place_on_table(mesh, T[int(np.argmax(p))], 0.4, (0.46, 0.02))
    scene = render_table_scene(DepthCamera(KinectSettings(), seed=3), mesh, T_true, T_world_cam=default_camera_pose())
    return scene, model_cloud(mesh, 4000)


def _surface_counts_unpruned(
    T_part_world: np.ndarray, context: np.ndarray, model: ModelCloud, s: RefineSettings
) -> tuple[int, int, int, int, int]:
    """``surface_check``'s counts with the tree over every seen point (the code before the speed-up)."""
    eye = geometry.transform_points(T_part_world, np.asarray(DEFAULT_EYE, float)[None])[0]
    d = model.points - eye
    dist = np.linalg.norm(d, axis=1)
    unit = d / dist[:, None]
    cand = -np.einsum("ij,ij->i", unit, model.normals) > np.cos(np.radians(s.max_incidence_deg))
    hit, _ = ray_depths(model, eye, model.points[cand])
    vis = np.flatnonzero(cand)[hit > dist[cand] - 1e-3]
    axis = model.center - eye
    axis /= np.linalg.norm(axis)
    e1 = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    basis = np.column_stack([e1, np.cross(axis, e1)])

    def plane(u: np.ndarray) -> np.ndarray:
        return (u @ basis) / (u @ axis)[:, None]

    obs = geometry.transform_points(T_part_world, context) - eye
    obs_dist = np.linalg.norm(obs, axis=1)
    ahead = obs @ axis > 0
    obs, obs_dist = obs[ahead], obs_dist[ahead]
    gap, j = cKDTree(plane(obs / obs_dist[:, None])).query(plane(unit[vis]), distance_upper_bound=s.ray_radius)
    found = np.isfinite(gap)
    delta = np.full(len(vis), np.nan)
    delta[found] = obs_dist[j[found]] - dist[vis][found]
    explained = int(np.sum(found & (np.abs(delta) <= s.surface_fit)))
    through = int(np.sum(found & (delta > s.surface_off)))
    return len(vis), explained, through, int(np.sum(found & (delta < -s.surface_off))), int(np.sum(~found))


@pytest.mark.parametrize("turn_deg", [0.0, 3.0, 40.0, 170.0])
def test_the_pruned_ray_tree_counts_what_the_full_one_does(scene_and_model, turn_deg: float) -> None:  # type: ignore[no-untyped-def]
    scene, model = scene_and_model
    cluster = scene.cloud[scene.frame.labels == 1]
    context = scene.cloud[np.linalg.norm(scene.cloud - cluster.mean(axis=0), axis=1) < 0.1]
    c = cluster.mean(axis=0)
    R = geometry.rot_z(np.radians(turn_deg))[:3, :3]
    T = geometry.from_rotation(R, c - R @ c) @ scene.T_world_part  # right pose, slightly and badly turned
    s = RefineSettings()
    got = check_surface(geometry.invert(T), context, DEFAULT_EYE, model, s)
    assert got.visible > 0
    assert (got.visible, got.explained, got.seen_through, got.in_front, got.missing) == _surface_counts_unpruned(
        geometry.invert(T), context, model, s
    )


def _violation_every_ray(T_part_world: np.ndarray, context: np.ndarray, model: ModelCloud, margin: float) -> float:
    """The free-space share with a ray cast to every seen point near the part (the code before the speed-up)."""
    local = geometry.transform_points(T_part_world, context)
    near = np.linalg.norm(local - model.center, axis=1) < 1.5 * model.radius + 0.01
    eye = geometry.transform_points(T_part_world, np.asarray(DEFAULT_EYE, float)[None])[0]
    hit, dist = ray_depths(model, eye, local[near])
    return float(np.mean(hit < dist - margin))


@pytest.mark.parametrize("shift", [0.0, 0.01, 0.03])
@pytest.mark.parametrize("turn_deg", [0.0, 20.0, 90.0])
def test_the_free_space_share_casts_fewer_rays_to_the_same_share(
    scene_and_model, turn_deg: float, shift: float
) -> None:  # type: ignore[no-untyped-def]
    scene, model = scene_and_model
    cluster = scene.cloud[scene.frame.labels == 1]
    context = scene.cloud[np.linalg.norm(scene.cloud - cluster.mean(axis=0), axis=1) < 0.1]
    c = cluster.mean(axis=0)
    R = geometry.rot_z(np.radians(turn_deg))[:3, :3]
    # Turned and lifted or sunk into the table (toward the camera at shift 0.03): shares from 0 to large.
    T = geometry.from_rotation(R, c - R @ c + [0.0, 0.0, shift - 0.01]) @ scene.T_world_part
    T_part_world = geometry.invert(T)
    margin = RefineSettings().occlusion_margin
    got = _free_space_violation(T_part_world, context, DEFAULT_EYE, model, margin)
    assert got == _violation_every_ray(T_part_world, context, model, margin)


def test_batched_near_shares_equal_one_query_per_pose(scene_and_model) -> None:  # type: ignore[no-untyped-def]
    scene, model = scene_and_model
    points = scene.cloud[scene.frame.labels == 1][::3]
    rng = np.random.default_rng(0)
    Ts = [scene.T_world_part @ geometry.from_rotvec(rng.normal(scale=0.2, size=3)) for _ in range(7)]
    one_by_one = []
    for T in Ts:
        local = geometry.transform_points(geometry.invert(T), points)
        d = model.scene.compute_distance(o3d.core.Tensor(local.astype(np.float32))).numpy()
        one_by_one.append(float(np.mean(d < 0.004)))
    assert near_shares(Ts, points, model, 0.004).tolist() == one_by_one
    assert len(near_shares([], points, model, 0.004)) == 0


@pytest.mark.parametrize("dist", [0.004, 0.012, 0.03])
def test_the_distance_grid_bounds_give_the_shares_of_the_exact_distances(scene_and_model, dist: float) -> None:  # type: ignore[no-untyped-def]
    scene, model = scene_and_model
    points = scene.cloud[scene.frame.labels == 1][::3]
    rng = np.random.default_rng(1)
    # Poses from right to far off: every point class (settled near, in the band, settled far, off the grid) occurs;
    # 0.03 is beyond the grid's margin, so off-grid points need the exact distance there.
    Ts = [scene.T_world_part @ geometry.from_rotvec(rng.normal(scale=s, size=3)) for s in (0.0, 0.05, 0.3, 1.0)]
    Ts += [
        geometry.compose(geometry.from_rotation(np.eye(3), rng.normal(scale=sc, size=3)), T)
        for T in Ts
        for sc in (0.01, 0.04)
    ]
    samples = SampleIndex.of(model)
    assert samples.step >= 0.002 and samples.distances.size <= 200_000 and samples.margin < 0.03
    exact = near_shares(Ts, points, model, dist)
    assert exact.max() == 1.0 and np.any((exact > 0.0) & (exact < 1.0))
    assert near_shares(Ts, points, model, dist, samples).tolist() == exact.tolist()


def test_the_distance_grid_bounds_hold_the_exact_distance(scene_and_model) -> None:  # type: ignore[no-untyped-def]
    _, model = scene_and_model
    samples = SampleIndex.of(model)
    rng = np.random.default_rng(2)
    lo, hi = np.asarray(model.mesh.bounds)
    local = rng.uniform(lo - 0.05, hi + 0.05, size=(20000, 3))  # inside, near and beyond the grid
    node, reach = samples.bounds(local)
    d = model.scene.compute_distance(o3d.core.Tensor(local.astype(np.float32))).numpy()
    on = np.isfinite(node)
    assert 0 < on.sum() < len(local)
    assert np.all(np.abs(d[on] - node[on]) <= reach[on])
    assert np.all(reach[on] <= samples.step * np.sqrt(3.0) / 2.0 + 1e-5)
    assert np.all(d[~on] > samples.margin)  # off the grid: farther than its margin
    node, reach = samples.bounds(np.array([[np.nan, 0.0, 0.0], [1e30, 0.0, 0.0]]))  # near nothing, no warning
    assert np.isinf(node).all() and not reach.any()


def test_a_verification_rejected_before_the_surface_check_keeps_its_verdict_and_score(scene_and_model) -> None:  # type: ignore[no-untyped-def]
    scene, model = scene_and_model
    s = RefineSettings()
    cluster = scene.cloud[scene.frame.labels == 1]
    context = scene.cloud[np.linalg.norm(scene.cloud - cluster.mean(axis=0), axis=1) < 0.1]
    T_off = scene.T_world_part @ geometry.from_rotvec([0.0, 0.0, 0.4])
    got = verify(T_off, cluster, context, DEFAULT_EYE, model, s, scene.table)
    assert not got.accepted and got.why.startswith("fitness") and np.isnan(got.coverage)
    # With no fitness, RMSE and free-space thresholds the same pose goes on to the surface check, and fitness
    # and violation (the score) are the ones computed before.
    loose = s.model_copy(update={"min_fitness": 0.0, "max_rmse": 1.0, "max_violation": 1.0})
    full = verify(T_off, cluster, context, DEFAULT_EYE, model, loose, scene.table)
    assert np.isfinite(full.coverage) and (full.fitness, full.violation) == (got.fitness, got.violation)
    right = verify(scene.T_world_part, cluster, context, DEFAULT_EYE, model, s, scene.table)
    assert right.accepted and np.isfinite(right.coverage)


@pytest.mark.slow
def test_the_near_twin_screen_finds_the_pose_of_the_full_pass(tmp_path: Path) -> None:
    # A prism with a hole: four near twins (turns the hole side hides) and six nudges, most of which fall back
    # onto the found pose; the screen skips their full ICP, and fewer ICP passes find the same pose.

    mesh = corpus_part("prism_hole_0").mesh
    mesh.export(tmp_path / "prism.stl")
    part = build_part(PartSpec(name="prism", mesh=str(tmp_path / "prism.stl"), mesh_units="m"))
    T, p = drop_rests(mesh, mesh.center_mass)
    got = {}
    for k in (0, 10):
        det = CvfhIcpDetector({"near_screen_iterations": k}, seed=0)
        runs = []
        for i, yaw in enumerate((0.3, 1.9)):
            T_true = place_on_table(mesh, T[int(np.argmax(p))], yaw, (0.47, 0.03))
            camera = DepthCamera(KinectSettings(), seed=i)
            sc = render_table_scene(camera, mesh, T_true, T_world_cam=default_camera_pose())
            runs.append(det.detect(sc.cloud, part, viewpoint=DEFAULT_EYE))
        got[k] = runs
    for full, screened in zip(got[0], got[10], strict=True):
        assert full.found == screened.found and full.reason == screened.reason
        if full.found:
            assert np.allclose(full.rough, screened.rough, atol=1e-9)
        assert screened.details["icp_passes"] < full.details["icp_passes"]
