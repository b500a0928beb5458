"""B's position in A during the approach, refitted with B's rotation in A held at the taught one.

While a person slides B into A, B's rotation relative to A is (nearly) the
assembled one; only its position changes. Two independent per-part PnPs
leave each frame's ``T_A_B`` as noisy as the worse part's pose (a single
small marker seen square-on tilts by degrees), and the tilt of A alone moves
B's apparent position in A by millimetres. Holding ``R_A_B`` fixed makes both
parts' corners one nearly rigid target: per frame the unknowns are
``T_cam_A`` (6) and B's origin in A (3), fitted to all corners of both parts
by Levenberg-Marquardt. Initial guesses come from each part's PnP pose and its
flip alternatives, so a flipped single-marker pose cannot trap the fit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares

from asmteach.core import geometry
from asmteach.plugins.detectors.aruco.pnp import MarkerObservation, PartPose

__all__ = ["ApproachPoint", "refit_with_rotation"]


@dataclass
class ApproachPoint:
    """One approach frame's refit: B's origin in A (metres) and the RMS reprojection error (pixels)."""

    index: int
    position: np.ndarray
    rms_px: float


def _points(obs: Sequence[MarkerObservation], pose: PartPose) -> tuple[np.ndarray, np.ndarray]:
    kept = [o for o in obs if o.marker_id in pose.marker_ids]
    return (
        np.concatenate([o.object_points for o in kept]).astype(np.float64),
        np.concatenate([o.corners_px for o in kept]).astype(np.float64),
    )


def refit_with_rotation(
    index: int,
    pose_a: PartPose,
    obs_a: Sequence[MarkerObservation],
    pose_b: PartPose,
    obs_b: Sequence[MarkerObservation],
    R_A_B: np.ndarray,
    K: np.ndarray,
    dist: np.ndarray,
) -> ApproachPoint:
    """Refit one frame with ``R_A_B`` (3x3, taught) fixed; see the module docstring."""
    obj_a, img_a = _points(obs_a, pose_a)
    obj_b, img_b = _points(obs_b, pose_b)
    # B's corners expressed in A's frame up to the unknown translation t: R_A_B @ p + t.
    obj_b_rot = obj_b @ R_A_B.T
    img = np.concatenate([img_a, img_b])

    def residuals(x: np.ndarray) -> np.ndarray:
        pts = np.concatenate([obj_a, obj_b_rot + x[6:9]])
        proj, _ = cv2.projectPoints(pts, x[:3], x[3:6], K, dist)
        return (proj.reshape(-1, 2) - img).ravel()

    def pack(T_cam_A: np.ndarray, t: np.ndarray) -> np.ndarray:
        rvec = cv2.Rodrigues(np.ascontiguousarray(T_cam_A[:3, :3]))[0].ravel()
        return np.concatenate([rvec, T_cam_A[:3, 3], t])

    # Guesses for T_cam_A: A's pose and its flips, and B's pose (and flips) carried to A with R_A_B fixed.
    t0 = (geometry.invert(pose_a.T_cam_part) @ pose_b.T_cam_part)[:3, 3]
    guesses = [T for T in [pose_a.T_cam_part] + [T for T, _ in pose_a.alternatives]]
    for Tb in [pose_b.T_cam_part] + [T for T, _ in pose_b.alternatives]:
        guesses.append(Tb @ geometry.invert(geometry.from_rotation(R_A_B, t0)))
    best = None
    for T in guesses:
        x0 = pack(T, t0)
        r0 = residuals(x0)
        if not np.all(np.isfinite(r0)):
            continue
        sol = least_squares(residuals, x0, method="lm", x_scale="jac", max_nfev=200)
        if best is None or sol.cost < best.cost:
            best = sol
    if best is None:
        return ApproachPoint(index, t0, float("inf"))
    rms = float(np.sqrt(np.mean(best.fun**2) * 2))
    return ApproachPoint(index, best.x[6:9].copy(), rms)
