"""The held part's pose measured from depth clouds, starting from where the plan believes it is."""

from __future__ import annotations

import numpy as np
import trimesh

from asmteach.core import geometry
from asmteach.core.perception.in_hand import measure_held_pose


def _l_block() -> trimesh.Trimesh:
    """An L of two boxes (60 x 20 x 20 mm and 20 x 20 x 40 mm): no symmetry to fall into."""
    foot = trimesh.creation.box(extents=[0.06, 0.02, 0.02])
    upright = trimesh.creation.box(extents=[0.02, 0.02, 0.04])
    upright.apply_translation([0.02, 0.0, 0.03])
    return trimesh.util.concatenate([foot, upright])


def _seen(mesh: trimesh.Trimesh, T: np.ndarray, eye: np.ndarray, n: int, sigma: float, seed: int) -> np.ndarray:
    """Surface points of ``mesh`` at ``T`` that face ``eye`` (world), with Gaussian noise (metres)."""
    pts, faces = trimesh.sample.sample_surface(mesh, n, seed=seed)
    world = geometry.transform_points(T, pts)
    normals = np.asarray(mesh.face_normals)[faces] @ T[:3, :3].T
    facing = np.einsum("ij,ij->i", normals, eye - world) > 0.0
    return world[facing] + np.random.default_rng(seed).normal(0.0, sigma, (int(facing.sum()), 3))


def test_a_held_part_is_measured_from_a_belief_4_mm_and_6_deg_off() -> None:
    mesh = _l_block()
    T_true = geometry.from_rpy(0.3, -0.2, 0.5, (0.4, 0.1, 0.25))
    eye = np.array([0.4, -0.6, 0.9])
    clouds = [
        _seen(mesh, T_true, eye, 6000, 0.0005, 1),
        _seen(mesh, T_true, np.array([0.9, 0.4, 0.8]), 3000, 0.0005, 2),
    ]
    # another part 40 mm below, in the same clouds, must not pull the fit
    other = trimesh.creation.box(extents=[0.05, 0.05, 0.02])
    T_other = geometry.from_rpy(0.0, 0.0, 0.0, (0.4, 0.1, 0.19))
    clouds.append(_seen(other, T_other, eye, 3000, 0.0005, 3))
    T_guess = T_true @ geometry.from_rpy(np.radians(6.0), 0.0, 0.0, (0.004, 0.0, 0.0))
    got = measure_held_pose(clouds, mesh, T_guess, others=[(other, T_other)], table_height=0.0)
    assert got.T_world_part is not None, got.why
    assert 1000.0 * geometry.translation_distance(got.T_world_part, T_true) < 0.5
    assert np.degrees(geometry.rotation_distance(got.T_world_part, T_true)) < 0.5
    assert got.fitness > 0.9


def test_too_few_points_measure_nothing_and_say_why() -> None:
    mesh = _l_block()
    T = geometry.from_rpy(0.0, 0.0, 0.0, (0.4, 0.1, 0.25))
    got = measure_held_pose([_seen(mesh, T, np.array([0.4, -0.6, 0.9]), 60, 0.0005, 1)], mesh, T)
    assert got.T_world_part is None
    assert got.why is not None and "points seen of the held part" in got.why


def test_points_of_another_shape_are_a_poor_fit_not_a_pose() -> None:
    mesh = _l_block()
    T = geometry.from_rpy(0.0, 0.0, 0.0, (0.4, 0.1, 0.25))
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.03)
    got = measure_held_pose([_seen(sphere, T, np.array([0.4, -0.6, 0.9]), 4000, 0.0005, 1)], mesh, T)
    assert got.T_world_part is None
    assert got.why is not None and "poor" in got.why


def test_the_measurement_tells_a_belief_10_deg_off_from_its_own_noise() -> None:
    mesh = _l_block()
    T_true = geometry.from_rpy(0.3, -0.2, 0.5, (0.4, 0.1, 0.25))
    clouds = [_seen(mesh, T_true, np.array([0.4, -0.6, 0.9]), 6000, 0.0015, 4)]
    got = measure_held_pose(clouds, mesh, T_true @ geometry.from_rpy(0.0, np.radians(3.0), 0.0))
    assert got.T_world_part is not None, got.why
    assert got.chi2(T_true) < 22.5  # the truth is within the measurement's noise
    assert got.chi2(T_true @ geometry.from_rpy(np.radians(10.0), 0.0, 0.0)) > 100.0
