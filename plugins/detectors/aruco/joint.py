"""Joint least-squares adjustment of ``T_A_B`` and every frame's ``T_cam_A`` over all corners at once.

Unknowns: ``x = [r_AB, t_AB, r_cam_A(0), t_cam_A(0), ...]`` (rotation vectors in
radians, translations in metres). A corner ``p`` of part A seen in frame ``k``
projects from ``T_cam_A(k) p``; a corner of B from ``T_cam_A(k) T_A_B p``.
Residuals are the pixel differences to the detected corners, all frames
projected in one vectorised call (:mod:`.projection`); the Jacobian is
analytic and sparse (each row touches the 6 shared and its frame's 6
unknowns), so :func:`scipy.optimize.least_squares` needs one residual and one
Jacobian evaluation per iteration instead of a finite-difference sweep.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import csr_matrix
from scipy.spatial.transform import Rotation

from asmteach.core import geometry
from asmteach.plugins.detectors.aruco.projection import (
    project_camera_points,
    rotation_matrices,
    skew,
    so3_left_jacobian,
)

__all__ = ["CornerSet", "adjust", "frame_rms", "jacobian", "pack_pose", "unpack_pose"]


@dataclass(frozen=True)
class CornerSet:
    """Corners of several frames stacked: ``n`` points in all."""

    obj: np.ndarray
    """``(n, 3)`` corner in its own part's frame (A or B), metres."""
    img: np.ndarray
    """``(n, 2)`` detected corner, pixels."""
    frame: np.ndarray
    """``(n,)`` int: index of the frame (0 .. n_frames - 1)."""
    is_b: np.ndarray
    """``(n,)`` bool: the corner belongs to part B."""
    n_frames: int

    @classmethod
    def build(cls, frames: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]) -> CornerSet:
        """From per-frame ``(obj_a, img_a, obj_b, img_b)`` (metres, pixels)."""
        obj, img, fr, isb = [], [], [], []
        for k, (oa, ia, ob, ib) in enumerate(frames):
            obj += [oa, ob]
            img += [ia, ib]
            fr += [np.full(len(oa) + len(ob), k)]
            isb += [np.zeros(len(oa), bool), np.ones(len(ob), bool)]
        return cls(
            np.concatenate(obj).astype(np.float64),
            np.concatenate(img).astype(np.float64),
            np.concatenate(fr),
            np.concatenate(isb),
            len(frames),
        )

    def subset(self, frames: Sequence[int]) -> CornerSet:
        """The given frames (repeats allowed), renumbered ``0 .. len(frames) - 1`` in that order."""
        groups = [np.flatnonzero(self.frame == f) for f in frames]
        idx = np.concatenate(groups) if groups else np.zeros(0, int)
        new_frame = np.repeat(np.arange(len(groups)), [len(g) for g in groups])
        return CornerSet(self.obj[idx], self.img[idx], new_frame, self.is_b[idx], len(groups))


def pack_pose(T: np.ndarray) -> np.ndarray:
    """``(6,)`` rotation vector (radians) and translation (metres) of a 4x4 pose."""
    return np.concatenate([Rotation.from_matrix(T[:3, :3]).as_rotvec(), T[:3, 3]])


def unpack_pose(x: np.ndarray) -> np.ndarray:
    """4x4 pose of ``(6,)`` rotation vector and translation."""
    return geometry.from_rotvec(x[:3], x[3:6])


def _evaluate(
    x: np.ndarray, cs: CornerSet, K: np.ndarray, dist: np.ndarray, jacobian: bool
) -> tuple[np.ndarray, csr_matrix | None]:
    """Residuals ``(2n,)`` pixels and, optionally, their sparse ``(2n, 6 + 6 m)`` Jacobian."""
    m = cs.n_frames
    r_ab, t_ab = x[:3], x[3:6]
    r_a, t_a = x[6:].reshape(m, 6)[:, :3], x[6:].reshape(m, 6)[:, 3:]
    R_ab = rotation_matrices(r_ab[None])[0]
    R_a = rotation_matrices(r_a)
    b = cs.is_b
    # Corner in A's frame, then in the camera's.
    rot_b = cs.obj @ R_ab.T
    u = np.where(b[:, None], rot_b + t_ab, cs.obj)
    Ru = np.einsum("nij,nj->ni", R_a[cs.frame], u)
    q = Ru + t_a[cs.frame]
    uv, J_q = project_camera_points(q, K, dist, jacobian=jacobian)
    res = (uv - cs.img).ravel()
    if not jacobian:
        return res, None
    assert J_q is not None
    n = len(q)
    blocks = np.zeros((n, 2, 12))
    # Frame block: d q / d r_a = -[R_a u]x J_l(r_a), d q / d t_a = I.
    dq_dra = -skew(Ru) @ so3_left_jacobian(r_a)[cs.frame]
    blocks[:, :, 6:9] = J_q @ dq_dra
    blocks[:, :, 9:12] = J_q
    # Shared block (B's corners only): d q / d r_ab = -R_a [R_ab p]x J_l(r_ab), d q / d t_ab = R_a.
    if np.any(b):
        Ra_b = R_a[cs.frame[b]]
        dq_drab = -Ra_b @ skew(rot_b[b]) @ so3_left_jacobian(r_ab[None])[0]
        blocks[b, :, 0:3] = J_q[b] @ dq_drab
        blocks[b, :, 3:6] = J_q[b] @ Ra_b
    cols = np.concatenate([np.broadcast_to(np.arange(6), (n, 6)), 6 + 6 * cs.frame[:, None] + np.arange(6)], axis=1)
    indices = np.repeat(cols, 2, axis=0).ravel()
    indptr = np.arange(0, 24 * n + 1, 12)
    return res, csr_matrix((blocks.reshape(-1), indices, indptr), shape=(2 * n, 6 + 6 * m))


def frame_rms(
    cs: CornerSet, T_A_B: np.ndarray, T_cam_A: Sequence[np.ndarray], K: np.ndarray, dist: np.ndarray
) -> np.ndarray:
    """``(n_frames,)`` RMS reprojection error per frame (pixels, over both image axes' norm)."""
    x = np.concatenate([pack_pose(T_A_B)] + [pack_pose(T) for T in T_cam_A])
    res, _ = _evaluate(x, cs, K, dist, jacobian=False)
    sq = np.bincount(cs.frame, weights=np.sum(res.reshape(-1, 2) ** 2, axis=1), minlength=cs.n_frames)
    cnt = np.bincount(cs.frame, minlength=cs.n_frames)
    return np.sqrt(sq / np.maximum(cnt, 1))


def adjust(
    cs: CornerSet,
    T_A_B: np.ndarray,
    T_cam_A: Sequence[np.ndarray],
    K: np.ndarray,
    dist: np.ndarray,
    *,
    f_scale: float = 0.5,
    max_rounds: int = 6,
    dense_max_unknowns: int = 400,
) -> tuple[np.ndarray, list[np.ndarray], int]:
    """Huber-robust adjustment (Huber scale ``f_scale`` pixels on each corner's error) from the given start.

    Up to ``dense_max_unknowns`` unknowns (about 65 frames): iteratively
    reweighted least squares, each round MINPACK's Levenberg-Marquardt
    (``method="lm"``) on the weighted residuals with the dense analytic
    Jacobian, the Huber weights ``min(1, f_scale / |e|)`` of each corner's
    error ``e`` refreshed between rounds until they settle. MINPACK's QR is
    its own unthreaded code: ``method="trf"`` with ``tr_solver="exact"`` takes
    as few steps but its SVD goes through the threaded BLAS, which on a
    loaded 2-core machine took over a second per step for a 500 x 140
    Jacobian. Larger problems use ``method="trf"`` with Huber loss on the
    sparse Jacobian (LSMR steps): more evaluations, each linear in the frames.

    Returns ``(T_A_B, [T_cam_A per frame], residual evaluations)``.
    """
    K = np.asarray(K, dtype=np.float64)
    dist = np.asarray(dist, dtype=np.float64)
    cache: dict[bytes, tuple[np.ndarray, csr_matrix]] = {}

    def both(x: np.ndarray) -> tuple[np.ndarray, csr_matrix]:
        # least_squares asks for the residuals and then the Jacobian at the same x: compute them together once.
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            res, jac = _evaluate(x, cs, K, dist, jacobian=True)
            assert jac is not None
            cache[key] = (res, jac)
        return cache[key]

    x = np.concatenate([pack_pose(T_A_B)] + [pack_pose(T) for T in T_cam_A])
    nfev = 0
    if x.size > dense_max_unknowns:
        sol = least_squares(
            lambda x: both(x)[0],
            x,
            jac=lambda x: both(x)[1],
            loss="huber",
            f_scale=f_scale,
            x_scale="jac",
            method="trf",
            tr_solver="lsmr",
            max_nfev=400,
        )
        x, nfev = sol.x, int(sol.nfev)
    else:
        w_prev = np.zeros(len(cs.obj))
        for _round in range(max_rounds):
            err = np.linalg.norm(both(x)[0].reshape(-1, 2), axis=1)
            w = np.minimum(1.0, f_scale / np.maximum(err, 1e-12))
            if np.max(np.abs(w - w_prev)) < 1e-3:
                break
            w_prev = w
            sw = np.repeat(np.sqrt(w), 2)
            sol = least_squares(
                lambda x, sw=sw: both(x)[0] * sw,
                x,
                jac=lambda x, sw=sw: both(x)[1].multiply(sw[:, None]).toarray(),
                method="lm",
                x_scale="jac",
            )
            x, nfev = sol.x, nfev + int(sol.nfev)
    poses = [unpack_pose(x[6 + 6 * k : 12 + 6 * k]) for k in range(cs.n_frames)]
    return unpack_pose(x[:6]), poses, nfev


def jacobian(
    cs: CornerSet, T_A_B: np.ndarray, T_cam_A: Sequence[np.ndarray], K: np.ndarray, dist: np.ndarray
) -> np.ndarray:
    """Dense ``(2n, 6 + 6 m)`` Jacobian of the corners' pixels by ``[r_AB, t_AB, r_cam_A(k), t_cam_A(k) ...]``."""
    x = np.concatenate([pack_pose(T_A_B)] + [pack_pose(T) for T in T_cam_A])
    _, J = _evaluate(x, cs, np.asarray(K, dtype=np.float64), np.asarray(dist, dtype=np.float64), jacobian=True)
    assert J is not None
    return J.toarray()
