"""Shared fixtures of the placements tests: set-1 parts, synthetic clouds and rough poses with known noise."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from asmteach.core import geometry
from asmteach.core.interfaces import PartModel
from asmteach.core.parts import build_part, load_structure

REPO = Path(__file__).resolve().parents[4]


def _part(structure: str, which: str) -> PartModel:
    path = REPO / "configs/parts/set1" / structure
    task = load_structure(path)
    return build_part(getattr(task, which), path.parent)


@pytest.fixture(scope="session")
def l_block() -> PartModel:
    """Asymmetric L-shaped block (set 1, l_corner part A)."""
    return _part("l_corner.yaml", "part_a")


@pytest.fixture(scope="session")
def t_slot_block() -> PartModel:
    """Block with a T-slot (set 1, t_slot part A); C2 on two placements."""
    return _part("t_slot.yaml", "part_a")


@pytest.fixture(scope="session")
def cube() -> PartModel:
    """A 40 mm cube (set 1, l_corner part B): C4 on every placement."""
    return _part("l_corner.yaml", "part_b")


def visible_cloud(
    mesh: trimesh.Trimesh,
    T_world_part: np.ndarray,
    camera: np.ndarray,
    *,
    n: int = 4000,
    noise: float = 0.0005,
    seed: int = 0,
) -> np.ndarray:
    """Points on the surface of ``mesh`` at ``T_world_part`` seen from ``camera`` (world, metres), with noise."""
    import open3d as o3d  # after asmteach (imported above) has preloaded libusb

    rng = np.random.default_rng(seed)
    world = mesh.copy()
    world.apply_transform(T_world_part)
    pts, face = trimesh.sample.sample_surface(world, n, seed=seed)
    normals = world.face_normals[face]
    to_cam = camera - pts
    facing = np.einsum("ij,ij->i", normals, to_cam) > 0
    pts = pts[facing]
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(world.vertices, dtype=np.float32)),
        o3d.core.Tensor(np.asarray(world.faces, dtype=np.uint32)),
    )
    d = np.linalg.norm(pts - camera, axis=1)
    rays = np.hstack([np.repeat(camera[None, :], len(pts), axis=0), (pts - camera) / d[:, None]]).astype(np.float32)
    hit = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
    pts = pts[np.abs(hit - d) < 1e-4]
    return pts + rng.normal(0.0, noise, pts.shape)


def table_cloud(
    center: np.ndarray, half: float, height: float, *, n: int = 3000, noise: float = 0.0005, seed: int = 1
) -> np.ndarray:
    """Points of a horizontal table patch around ``center`` (x, y) at ``height``."""
    rng = np.random.default_rng(seed)
    xy = center[:2] + rng.uniform(-half, half, (n, 2))
    z = height + rng.normal(0.0, noise, n)
    return np.column_stack([xy, z])


def perturb(T: np.ndarray, rng: np.random.Generator, *, rot_deg: float, yaw_deg: float, trans: float) -> np.ndarray:
    """A rough pose: ``T`` with a random tilt of ``rot_deg``, a yaw error of ``yaw_deg`` and a shift of ``trans`` m."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    tilt = geometry.from_rotvec(axis * np.radians(rot_deg))
    yaw = geometry.rot_z(np.radians(yaw_deg) * rng.choice([-1.0, 1.0]))
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    out = yaw @ tilt @ T
    out[:3, 3] = T[:3, 3] + direction * trans
    return out


@pytest.fixture(scope="session")
def scene() -> SimpleNamespace:
    """The synthetic-scene helpers: ``visible_cloud``, ``table_cloud``, ``perturb``."""
    return SimpleNamespace(visible_cloud=visible_cloud, table_cloud=table_cloud, perturb=perturb)
