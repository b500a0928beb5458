"""How well the seen points pin a ``cvfh_icp`` pose down, and the rival poses when they do not.

* :func:`free_axes`: the part's axes of revolution (a turn about one is the same pose);
* :func:`weakest_turn` / :func:`rotation_sigma_deg`: the rotation's standard deviation in its weakest direction,
  from a linearised point-to-plane registration of the seen points with the Kinect's noise;
* :func:`pin_rivals`: the pose turned both ways by ``pin_sigmas`` sigma about that direction when it is not
  pinned (listed in ``details["ambiguous"]`` so another view can judge), directions about which every turn
  keeps the surface (:class:`~asmteach.core.symmetry.near.NearSymmetry`) left out.

All poses are ``T_world_part`` (world frame, metres, z up); angles in degrees.
"""

from __future__ import annotations

import numpy as np
import trimesh

from asmteach.core import geometry
from asmteach.core.clouds import depth_sigma
from asmteach.core.symmetry import SymmetryFinder, axis_rotations, principal_frame
from asmteach.plugins.detectors.cvfh.pose_search import ClusterJob, Prepared
from asmteach.plugins.detectors.cvfh.resting import table_frame
from asmteach.plugins.detectors.cvfh.settings import CvfhSettings

__all__ = ["free_axes", "pin_rivals", "rotation_sigma_deg", "weakest_turn"]


def free_axes(mesh: trimesh.Trimesh, com: np.ndarray, tol: float) -> np.ndarray:
    """``(m, 3)`` principal axes (part frame, unit) the part turns about freely: an axis of revolution (turns of
    7 and 31 deg map its surface onto itself within ``tol`` metres, as :func:`asmteach.core.symmetry.
    equivalent_transforms` tests it). A turn about one gives the same pose, so the view need not pin it."""
    com = np.asarray(com, float)
    finder = SymmetryFinder(mesh, np.asarray(mesh.convex_hull.vertices), com, tol=tol, corners=False)
    axes = [a for a in principal_frame(mesh).T if all(finder.maps(R) for R in axis_rotations(a, np.radians([7, 31])))]
    return np.asarray(axes, float).reshape(-1, 3)


def rotation_sigma_deg(T_world_part: np.ndarray, job: ClusterJob, prep: Prepared, inlier: float) -> float:
    """The largest standard deviation (deg) of the pose's rotation the seen points leave, any direction
    (:func:`weakest_turn`'s first value)."""
    return weakest_turn(T_world_part, job, prep, inlier)[0]


def weakest_turn(
    T_world_part: np.ndarray, job: ClusterJob, prep: Prepared, inlier: float, free: np.ndarray | None = None
) -> tuple[float, np.ndarray, np.ndarray]:
    """``(sigma_deg, axis, centre)``: the largest standard deviation (deg) of the pose's rotation the seen points
    leave, the unit turn axis (world frame) it is about and the seen centroid (world, metres) it turns about.
    ``free``: part-frame axes left out besides :attr:`Prepared.free` (a turn found to keep the surface).

    Linearised point-to-plane registration: each cluster point within ``inlier`` metres of the model at
    the pose constrains the motion along the model's normal at its nearest model point; its noise along
    that normal is the Kinect's depth noise along the camera ray (:func:`asmteach.core.clouds.depth_sigma`)
    and a 0.5-pixel lateral jitter across it. The information matrix of the 6 pose parameters (turn about
    the seen centroid, shift) gives the covariance; the turn block's largest eigenvalue, with the
    translation free (a shift may make up for part of a turn) and turns about an axis of revolution left
    out (:func:`free_axes`), is the weakest direction's variance.

    The points are the voxel-reduced cluster ICP registers (``job.icp_in``, one per 3 mm voxel), not every
    pixel: a Kinect's neighbouring pixels share their error (its correlation window, the lateral blur), and
    counting each as independent information claimed more than the view holds: ``ff_duck`` scene 1 had 1.49 deg
    from its 272 pixels (3 sigma within 5 deg) and was found 6.5 deg off, the noise pulling ICP from the true
    pose as far; its 189 voxels give 1.82 deg.
    """
    cluster, eye = job.icp_in, np.asarray(job.eye, float)
    T_pw = geometry.invert(T_world_part)
    local = geometry.transform_points(T_pw, cluster)
    import open3d as o3d

    near = prep.model.scene.compute_closest_points(o3d.core.Tensor(local.astype(np.float32)))
    q_local = near["points"].numpy().astype(float)
    ok = np.linalg.norm(q_local - local, axis=1) < inlier
    if ok.sum() < 10:
        return float("inf"), np.array([0.0, 0.0, 1.0]), cluster.mean(axis=0)
    R = T_world_part[:3, :3]
    q = geometry.transform_points(T_world_part, q_local[ok])
    n = near["primitive_normals"].numpy().astype(float)[ok] @ R.T
    p = cluster[ok]
    ray = p - eye
    rng = np.linalg.norm(ray, axis=1)
    cos = np.abs(np.einsum("ij,ij->i", n, ray / rng[:, None]))
    lateral = rng * 0.5 / 525.0  # 0.5 px of a Kinect v1's 525 px focal length, metres
    var = (depth_sigma(rng) * cos) ** 2 + lateral**2 * (1.0 - cos**2)
    c = p.mean(axis=0)
    J = np.hstack([np.cross(q - c, n), n])  # d(residual) / d(turn, shift)
    extra = np.zeros((0, 3)) if free is None else np.asarray(free, float).reshape(-1, 3)
    free_w = _orthonormal(np.vstack([prep.free.reshape(-1, 3), extra]) @ R.T)
    # turns orthogonal to the free axes: an orthonormal basis of their complement
    basis = np.linalg.svd(np.eye(3) - free_w.T @ free_w)[0][:, : 3 - len(free_w)] if len(free_w) else np.eye(3)
    if basis.shape[1] == 0:
        return 0.0, np.array([0.0, 0.0, 1.0]), c
    Jr = np.hstack([J[:, :3] @ basis, J[:, 3:]])
    info = (Jr / var[:, None]).T @ Jr
    k = basis.shape[1]
    # The turn's information with the shift free: the Schur complement of the shift block (its pseudo-inverse: a
    # shift nothing pins, a tube seen from the side along its axis, leaves the turns alone).
    schur = info[:k, :k] - info[:k, k:] @ np.linalg.pinv(info[k:, k:]) @ info[k:, :k]
    values, vectors = np.linalg.eigh(schur)
    axis = basis @ vectors[:, 0]
    axis /= np.linalg.norm(axis)
    if values[0] <= 0.0:
        return float("inf"), axis, c
    return float(np.degrees(np.sqrt(1.0 / values[0]))), axis, c


def _orthonormal(rows: np.ndarray) -> np.ndarray:
    """An orthonormal basis (rows) of the span of ``rows`` ((m, 3)): free axes need not be perpendicular."""
    if not len(rows):
        return rows
    _, sv, vt = np.linalg.svd(rows, full_matrices=False)
    return vt[sv > 1e-6 * sv.max()]


def pin_rivals(
    T: np.ndarray, job: ClusterJob, prep: Prepared, s: CvfhSettings, at_rest: bool = False
) -> tuple[float, list[np.ndarray]]:
    """``(sigma_deg, rivals)``: the pose's rotation uncertainty in its weakest direction, and, when ``pin_sigmas``
    times it exceeds ``distinct_deg``, ``T`` turned that many sigmas both ways about that direction (through
    the seen centroid; world frame, metres); no rivals when the view pins the pose down. ``at_rest``: ``T`` rests
    on a stable rest on the table (:func:`~asmteach.plugins.detectors.cvfh.pose_search.rest_pass`), which pins
    its tilts; only the turn about the table normal is the view's to pin.

    A weakest direction about which every turn, all round, keeps the part's surface in place (``prep.same``:
    an axis of revolution the listed symmetries miss) is no uncertainty of the answer: it is left out, as
    :func:`free_axes` are, and the next weakest direction judged. All round, not only within the sigmas: along
    such a direction ICP's objective is flat but for the facets, the linearised sigma says nothing about where
    the truth is, and the corpus torus, found 11.9 deg about its axis from the truth, is 0.52 mm off there.
    """
    free = np.zeros((0, 3))
    if at_rest:
        free = table_frame(job.table)[:3, :2].T @ T[:3, :3]  # the turns about axes along the table, part frame
    for _ in range(3):
        sigma, axis, centre = weakest_turn(T, job, prep, s.refine.inlier_distance, free)
        if s.pin_sigmas * sigma <= s.distinct_deg:
            return sigma, []
        turn = min(s.pin_sigmas * sigma, 90.0)  # an unpinned turn of a sphere-like part: 90 deg shows it
        rivals = [_turned(T, axis, centre, a) for a in (turn, -turn)]
        if prep.same is None or not all(
            prep.same.same(T, _turned(T, axis, centre, a), s.distinct_mm) for a in (turn, -turn, *_ALL_ROUND)
        ):
            return sigma, rivals
        free = np.vstack([free, T[:3, :3].T @ axis])  # every turn keeps the surface: a symmetry, part frame
    return sigma, rivals


_ALL_ROUND = tuple(range(3, 360, 3))
"""Turns (deg) that must all keep the surface for a direction to be left out of the pin check."""


def _turned(T: np.ndarray, axis: np.ndarray, centre: np.ndarray, deg: float) -> np.ndarray:
    """``T`` turned by ``deg`` about the world ``axis`` through ``centre`` (metres)."""
    R = geometry.from_rotvec(np.radians(deg) * axis)[:3, :3]
    return geometry.from_rotation(R, centre - R @ centre) @ T
