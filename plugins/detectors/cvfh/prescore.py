"""Cheap scores of pose hypotheses for ``cvfh_icp``: the share of observed points near the model, the support gap.

Poses are ``T_world_part`` (4x4, metres); points are in the world frame (metres). These rank hypotheses before
ICP (the pre-score) and coarse ICP results before the fine one; the verification proper is
:func:`asmteach.core.perception.registration.verify`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core import geometry
from asmteach.core.models import TablePlane
from asmteach.core.perception.registration import ModelCloud

__all__ = ["SampleIndex", "near_shares", "support_gap"]

_ROUNDING = 1e-6
"""Metres added to every bound: the exact distances are float32 (Open3D), a few 1e-9 m off the true ones."""


@dataclass
class SampleIndex:
    """The model's exact surface distance sampled on a regular grid (part frame, metres), for threshold tests.

    Distance to a surface changes no faster than the point moves, so a point ``r`` from its nearest grid node
    lies between ``d_node - r`` and ``d_node + r`` from the surface: a test ``distance < dist`` is settled by a
    table look-up for every point whose interval lies on one side of ``dist``, and needs the exact distance (a
    ray-casting query, ~1.4 us a point) only for the rest. Points off the grid, which covers the model's
    bounding box grown by ``margin``, are farther than ``margin`` from the surface.
    """

    origin: np.ndarray
    """(3,) the first node, part frame, metres."""
    step: float
    """node spacing, metres"""
    distances: np.ndarray
    """(nx, ny, nz) float32 distance of each node to the surface, metres."""
    margin: float
    """metres the grid reaches beyond the model's bounding box"""

    @classmethod
    def of(cls, model: ModelCloud, seed: int = 0, margin: float = 0.02, max_nodes: int = 200_000) -> SampleIndex:
        """The grid of ``model.mesh``: 2 mm steps, coarser when the box would need more than ``max_nodes``.

        ``seed`` is unused (the grid is deterministic); it is kept so that callers pass the detector's seed as
        for every other prepared item. The build costs ~0.1-0.3 s a part (one distance query per node).
        """
        import open3d as o3d

        del seed
        lo, hi = np.asarray(model.mesh.bounds, dtype=float)
        lo, hi = lo - margin, hi + margin
        step = max(0.002, float(np.prod(hi - lo) / max_nodes) ** (1.0 / 3.0))
        n = np.ceil((hi - lo) / step).astype(np.int64) + 1
        axes = [lo[k] + step * np.arange(n[k]) for k in range(3)]
        nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        d = model.scene.compute_distance(o3d.core.Tensor(nodes.astype(np.float32))).numpy()
        return cls(lo, step, d.reshape(*n), margin)

    def bounds(self, local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(node distance, reach)`` of ``(n, 3)`` part-frame points: the surface is within ``reach`` of it.

        Off the grid the node distance is ``inf`` (farther than :attr:`margin`) and the reach 0.
        """
        shape = np.asarray(self.distances.shape)
        q = np.rint((local - self.origin) / self.step)
        on = np.all((q >= 0) & (q < shape), axis=1)  # False for a non-finite point too: it is near nothing
        idx = q[on].astype(np.int64)
        node = np.full(len(local), np.inf)
        node[on] = self.distances.ravel()[(idx[:, 0] * shape[1] + idx[:, 1]) * shape[2] + idx[:, 2]]
        off = local[on] - (self.origin + self.step * idx)
        reach = np.zeros(len(local))
        reach[on] = np.sqrt(np.einsum("ij,ij->i", off, off)) + _ROUNDING
        return node, reach


def near_shares(
    Ts: list[np.ndarray], points: np.ndarray, model: ModelCloud, dist: float, samples: SampleIndex | None = None
) -> np.ndarray:
    """Share of ``points`` (world) within ``dist`` (metres) of the model surface at each pose ``T_world_part``.

    One distance query for all poses (each point's distance is computed on its own, so the shares are the
    ones separate queries give). With ``samples`` its grid settles most points (the exact distance is asked
    only for those whose bounds straddle ``dist``), giving the same shares.
    """
    if not Ts:
        return np.zeros(0)
    local = np.concatenate([geometry.transform_points(geometry.invert(T), points) for T in Ts])
    if samples is None:
        near = _exact(model, local) < dist
    else:
        node, reach = samples.bounds(local)
        near = node < dist - reach
        unsure = ~near & (node <= dist + reach)
        if dist > samples.margin:  # off the grid is only known to be farther than the margin
            unsure |= np.isinf(node)
        if unsure.any():
            near[unsure] = _exact(model, local[unsure]) < dist
    return np.mean(near.reshape(len(Ts), -1), axis=1)


def _exact(model: ModelCloud, local: np.ndarray) -> np.ndarray:
    """Ray-casting distances (float32, metres) of part-frame points to the model surface."""
    import open3d as o3d

    return model.scene.compute_distance(o3d.core.Tensor(local.astype(np.float32))).numpy()


def support_gap(T_world_part: np.ndarray, model: ModelCloud, table: TablePlane) -> float:
    """Height (metres) of the model's lowest point above the table at this pose."""
    n = np.asarray(table.normal, dtype=float)
    return float(np.min(geometry.transform_points(T_world_part, model.hull_vertices) @ n) - table.height)
