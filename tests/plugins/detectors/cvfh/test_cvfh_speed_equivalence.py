"""The speed-ups of issue 27 change no result: the pruned ray tree of ``surface_check`` and the batched
distance query of the pre-score give exactly what the unpruned / one-pose-at-a-time computations give."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
from scipy.spatial import cKDTree

from asmteach.core import geometry
from asmteach.core.corpus import corpus_part
from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings
from asmteach.core.perception.registration import ModelCloud, RefineSettings, model_cloud, ray_depths, surface_check
from asmteach.plugins.detectors.cvfh.detector import _near_shares
from asmteach.plugins.detectors.cvfh.scenes import DEFAULT_EYE, default_camera_pose, place_on_table, render_table_scene


@pytest.fixture(scope="module")
def scene_and_model():  # type: ignore[no-untyped-def]
    """A prism with a hole lying on the table, seen by the scene Kinect; its model cloud."""
    import trimesh

    mesh = corpus_part("prism_hole_0").mesh
    T, p = trimesh.poses.compute_stable_poses(mesh, center_mass=np.asarray(mesh.center_mass))
    T_true = place_on_table(mesh, T[int(np.argmax(p))], 0.4, (0.46, 0.02))
    scene = render_table_scene(DepthCamera(KinectSettings(), seed=3), mesh, T_true, T_world_cam=default_camera_pose())
    return scene, model_cloud(mesh, 4000)


def _surface_counts_unpruned(T_part_world: np.ndarray, context: np.ndarray, model: ModelCloud,
                             s: RefineSettings) -> tuple[int, int, int, int, int]:
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
    got = surface_check(geometry.invert(T), context, DEFAULT_EYE, model, fit=s.surface_fit, off=s.surface_off,
                        ray_radius=s.ray_radius, max_incidence_deg=s.max_incidence_deg)
    assert got.visible > 0
    assert (got.visible, got.explained, got.seen_through, got.in_front, got.missing) == _surface_counts_unpruned(
        geometry.invert(T), context, model, s)


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
    assert _near_shares(Ts, points, model, 0.004).tolist() == one_by_one
    assert len(_near_shares([], points, model, 0.004)) == 0
