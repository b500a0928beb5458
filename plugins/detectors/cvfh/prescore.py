"""Cheap scores of pose hypotheses for ``cvfh_icp``: the share of observed points near the model, the support gap.

Poses are ``T_world_part`` (4x4, metres); points are in the world frame (metres). These rank hypotheses before
ICP (the pre-score) and coarse ICP results before the fine one; the verification proper is
:func:`asmteach.core.perception.registration.verify`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core import geometry
from asmteach.core.models import TablePlane
from asmteach.core.perception.registration import ModelCloud

__all__ = ["SampleIndex", "near_shares", "support_gap"]


@dataclass
class SampleIndex:
    """A k-d tree over the model's surface samples (part frame, metres) and how far they leave the surface uncovered.

    The distance of a point to the nearest sample bounds its distance to the surface from above, and from
    below once ``cover`` (the largest distance from a surface point to its nearest sample) is taken off: a
    threshold test then needs the exact distance (a ray-casting query, ~1.4 us a point) only for the points
    between the two.
    """

    tree: cKDTree
    cover: float

    @classmethod
    def of(cls, model: ModelCloud, seed: int = 0) -> SampleIndex:
        """The index of ``model.points``; ``cover`` from 20 000 seeded surface points, with a 1.5x margin."""
        import trimesh

        tree = cKDTree(model.points)
        probe, _ = trimesh.sample.sample_surface(model.mesh, 20000, seed=seed + 7)
        # The largest gap of 20 000 random points under-estimates the true one by a little: 1.5x covers it.
        return cls(tree, 1.5 * float(tree.query(probe)[0].max()))


def near_shares(
    Ts: list[np.ndarray], points: np.ndarray, model: ModelCloud, dist: float, samples: SampleIndex | None = None
) -> np.ndarray:
    """Share of ``points`` (world) within ``dist`` (metres) of the model surface at each pose ``T_world_part``.

    One distance query for all poses (each point's distance is computed on its own, so the shares are the
    ones separate queries give). With ``samples`` the k-d tree settles most points (nearer than ``dist`` to a
    sample, or farther than ``dist + cover`` from all) and the exact distance is asked only for the rest.
    """
    import open3d as o3d

    if not Ts:
        return np.zeros(0)
    local = np.concatenate([geometry.transform_points(geometry.invert(T), points) for T in Ts])
    if samples is None:
        d = model.scene.compute_distance(o3d.core.Tensor(local.astype(np.float32))).numpy()
        return np.mean((d < dist).reshape(len(Ts), -1), axis=1)
    ds, _ = samples.tree.query(local, distance_upper_bound=dist + samples.cover)
    near = ds < dist
    unsure = ~near & np.isfinite(ds)
    if unsure.any():
        d = model.scene.compute_distance(o3d.core.Tensor(local[unsure].astype(np.float32))).numpy()
        near[unsure] = d < dist
    return np.mean(near.reshape(len(Ts), -1), axis=1)


def support_gap(T_world_part: np.ndarray, model: ModelCloud, table: TablePlane) -> float:
    """Height (metres) of the model's lowest point above the table at this pose."""
    n = np.asarray(table.normal, dtype=float)
    return float(np.min(geometry.transform_points(T_world_part, model.hull_vertices) @ n) - table.height)
