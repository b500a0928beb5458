"""Approximate symmetries found near a given motion: when two poses of a part are the same answer.

:func:`~asmteach.core.symmetry.part_symmetries` lists the rotations that map a part onto itself within
0.5 mm, from a finite set of candidates (cube group, cyclic groups about principal axes, their flips).
A tessellated torus or ball has symmetries that are only approximate and nearly continuous: the torus
of the corpus maps onto itself within 0.53 mm after any turn about its axis, and a 1002-face mesh gives
no candidate list that holds them all. A detector then sees two poses whose surfaces coincide and
calls them rivals; a benchmark calls one of them 12 deg off.

:class:`NearSymmetry` answers the question for one pair of poses instead of listing the group: the offset
``D = inv(B) @ A`` (part frame) is a symmetry when the surface moved by it stays within ``tol`` of the
surface (:meth:`NearSymmetry.gap`, the larger of the two directed Hausdorff distances over surface
samples), its translation refit first (the two poses carry their own registration noise, and the pose
tolerance allows 5 mm). ``A`` is then the same answer as ``B`` (:meth:`NearSymmetry.same`): the two put
the part's surface in the same place within ``tol``, the rule ``part_symmetries`` applies to its listed
rotations, found where it is needed. The turn between them may be any: the corpus torus turned 8 or 20 deg
about its axis is the same answer (0.48 / 0.21 mm), turned 12 deg it is not (0.52 mm: halfway between two
of its 16 exact turns it is 0.53 mm off), nor is a hex peg turned 8 deg (1.1 mm). A point-to-plane ICP of
the surface onto itself is no way to find a nearer symmetry: the facets' exact symmetries pull it 8-12 deg
away.

Units: metres, radians (``apart`` returns mm); frames: the part frame.
"""

from __future__ import annotations

import numpy as np
import trimesh

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core import geometry

import open3d as o3d  # isort: skip

__all__ = ["NearSymmetry"]


class NearSymmetry:
    """Tests part-frame motions of one mesh for approximate symmetry (see the module docstring).

    ``tol`` (metres) is how far the moved surface may stray from the surface: 0.5 mm, the tolerance of
    :func:`~asmteach.core.symmetry.part_symmetries`. ``samples`` surface points (seeded, evenly spread)
    stand for the surface in both directions of the gap.
    """

    def __init__(self, mesh: trimesh.Trimesh, tol: float = 0.0005, samples: int = 2000, seed: int = 0) -> None:
        pts, faces = trimesh.sample.sample_surface_even(mesh, samples, seed=seed)
        if len(pts) < samples // 2:  # even sampling rejects many on small meshes: top up uniformly
            more, more_faces = trimesh.sample.sample_surface(mesh, samples - len(pts), seed=seed + 1)
            pts, faces = np.vstack([pts, more]), np.concatenate([faces, more_faces])
        self.tol = float(tol)
        self.points = np.asarray(pts, float)
        self.radius = float(np.max(np.linalg.norm(self.points - self.points.mean(axis=0), axis=1)))
        self._scene = o3d.t.geometry.RaycastingScene()
        self._scene.add_triangles(
            o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
            o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)),
        )
        self._pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(self.points))
        self._pcd.normals = o3d.utility.Vector3dVector(np.asarray(mesh.face_normals, float)[faces])

    def _farthest(self, S: np.ndarray) -> float:
        moved = geometry.transform_points(S, self.points).astype(np.float32)
        return float(self._scene.compute_distance(o3d.core.Tensor(moved)).numpy().max())

    def gap(self, S: np.ndarray) -> float:
        """Largest distance (metres) of the surface moved by ``S`` (4x4, part frame) from the surface, the
        larger of ``S`` and its inverse (a motion that folds a bump onto a flat face fails one of them)."""
        return max(self._farthest(S), self._farthest(geometry.invert(S)))

    def _shifted(self, S: np.ndarray, iterations: int = 6) -> np.ndarray:
        """``S`` with its translation refit (point-to-plane, the turn kept) so the moved surface best lies on
        the surface: an offset measured between two registered poses carries their registration noise."""
        S = np.array(S, dtype=float)
        for _ in range(iterations):
            moved = geometry.transform_points(S, self.points)
            near = self._scene.compute_closest_points(o3d.core.Tensor(moved.astype(np.float32)))
            q = near["points"].numpy().astype(float)
            n = near["primitive_normals"].numpy().astype(float)
            r = np.einsum("ij,ij->i", n, q - moved)
            t, *_ = np.linalg.lstsq(n, r, rcond=None)
            S[:3, 3] += t
            if np.linalg.norm(t) < 1e-6:
                break
        return S

    def apart(self, A: np.ndarray, B: np.ndarray) -> float:
        """Millimetres between the origins of pose ``A`` and ``B @ S``, ``S`` the offset ``inv(B) @ A`` with
        its translation refit (:meth:`_shifted`), when ``S`` maps the surface within ``tol``; ``inf`` when it
        does not (4x4 poses, any common frame).

        No turn is allowed on top of ``S``: any motion near the identity maps within ``tol`` (a hex peg turned
        3 deg, 0.46 mm), so a 5 deg allowance added to it would pass a hex peg 8 deg off.
        """
        S = self._shifted(geometry.invert(B) @ A)
        if self.gap(S) > self.tol:
            return float("inf")
        return 1000.0 * float(np.linalg.norm(A[:3, 3] - (B @ S)[:3, 3]))

    def same(self, A: np.ndarray, B: np.ndarray, mm: float = 5.0) -> bool:
        """Whether poses ``A`` and ``B`` put the surface in the same place within ``tol``, up to a shift of at
        most ``mm`` (the pose tolerance's) that the refit removes."""
        return self.apart(A, B) <= mm
