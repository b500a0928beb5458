"""Small Open3D helpers the perception modules share: point clouds from arrays, the one-thread block."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

import asmteach.core  # noqa: F401  (loads libusb before open3d)

import open3d as o3d  # isort: skip

__all__ = ["one_thread", "to_o3d"]


def to_o3d(points: np.ndarray, normals: np.ndarray | None = None) -> o3d.geometry.PointCloud:
    """An Open3D point cloud of ``(n, 3)`` points (and normals), in their own frame and units."""
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.ascontiguousarray(points, dtype=np.float64)))
    if normals is not None:
        pc.normals = o3d.utility.Vector3dVector(np.ascontiguousarray(normals, dtype=np.float64))
    return pc


@contextmanager
def one_thread() -> Iterator[None]:
    """Open3D on one thread inside the block (the previous limit is restored after).

    Open3D (0.20, oneAPI TBB) sums ICP's normal equations over threads in the order the scheduler
    runs them, so the same input gave poses a few ULPs apart from one run to the next; through
    the corrector, the regrasp graph and T-RRT those ULPs grew into another plan. On one thread the
    sum has one order. The demo's clusters are a few thousand points: the cost is not measurable.
    Older Open3D (OpenMP) has no such call: there ``OMP_NUM_THREADS=1`` does it.
    """
    limit = getattr(o3d.utility, "set_max_threads", None)
    if limit is None or o3d.utility.get_max_threads() == 1:
        yield  # already one thread (an enclosing block): changing the limit twice per ICP costs a TBB re-sync
        return
    before = o3d.utility.get_max_threads()
    limit(1)
    try:
        yield
    finally:
        limit(before)
