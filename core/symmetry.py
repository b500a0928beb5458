"""Symmetries of a rigid part: the proper rotations that map its surface onto itself.

A pose of a symmetric part is only defined up to these rotations: a
detector may return any of them, and an assembly is right when it matches
the taught one up to them. Frames: part frame; units: metres.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from asmteach.core import geometry

__all__ = ["part_symmetries"]


def part_symmetries(mesh: trimesh.Trimesh, com: np.ndarray, tol: float = 0.0005) -> list[np.ndarray]:
    """Proper rotations (``(4, 4)``, part frame, about the centre of mass) that map the part onto itself.

    Candidates are the 24 rotations of the cube group about the part-frame
    axes and about the principal axes of inertia; a candidate is kept when
    every one of 1500 surface samples lands within ``tol`` metres of the
    surface. Placement symmetry yaws only cover turns about the vertical; a
    part lying on its side can also be symmetric about a horizontal axis
    (the T-slider), which this finds too.
    """
    import open3d as o3d

    cube = [R.as_matrix() for R in Rotation.create_group("O")]
    frames = [np.eye(3), np.asarray(mesh.principal_inertia_vectors, dtype=float).T]
    if np.linalg.det(frames[1]) < 0:
        frames[1][:, 2] *= -1.0
    pts, _ = trimesh.sample.sample_surface(mesh, 1500, seed=0)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)),
    )
    found: list[np.ndarray] = []
    for F in frames:
        for C in cube:
            R = F @ C @ F.T
            if any(np.allclose(R, S[:3, :3], atol=1e-6) for S in found):
                continue
            moved = (pts - com) @ R.T + com
            d = scene.compute_distance(o3d.core.Tensor(moved.astype(np.float32))).numpy()
            if float(d.max()) < tol:
                found.append(geometry.from_rotation(R, com - R @ com))
    return found or [np.eye(4)]
