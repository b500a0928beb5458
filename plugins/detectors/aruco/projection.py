"""OpenCV's camera projection in numpy, vectorised over many points and poses, with analytic Jacobians.

``cv2.projectPoints`` takes one pose per call; the joint adjustment over all
frames needs every frame's corners projected at once, and its Jacobian. This
module evaluates exactly OpenCV's model (``calib3d`` ``projectPoints``): for a
point ``(X, Y, Z)`` in the camera frame (metres), ``x' = X / Z``, ``y' = Y / Z``
(``1 / Z`` taken as 1 when ``Z == 0``, as OpenCV does), ``r2 = x'^2 + y'^2``,

    x'' = x' (1 + k1 r2 + k2 r4 + k3 r6) / (1 + k4 r2 + k5 r4 + k6 r6)
          + 2 p1 x'y' + p2 (r2 + 2 x'^2) + s1 r2 + s2 r4
    y'' = y' (...) + p1 (r2 + 2 y'^2) + 2 p2 x'y' + s3 r2 + s4 r4

then the sensor tilt ``(tauX, tauY)`` as a homography on ``(x'', y'', 1)``,
then ``u = fx x''' + cx``, ``v = fy y''' + cy`` (OpenCV reads only ``fx, fy,
cx, cy`` of ``K``; a skew ``K[0, 1]`` is ignored there and here). Distortion
vectors of 4, 5, 8, 12 or 14 coefficients are accepted, OpenCV's order.

Rotations are rotation vectors (radians, OpenCV's ``Rodrigues``); their
Jacobians use the left Jacobian of SO(3): ``d(R(r) p)/dr = -[R p]x J_l(r)``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = [
    "dist14",
    "project_camera_points",
    "rotation_matrices",
    "skew",
    "so3_left_jacobian",
    "tilt_matrix",
]


def dist14(dist: np.ndarray | list[float]) -> np.ndarray:
    """OpenCV distortion coefficients padded to the full 14 ``(k1 k2 p1 p2 k3 k4 k5 k6 s1 s2 s3 s4 tauX tauY)``."""
    d = np.asarray(dist, dtype=np.float64).ravel()
    if d.size not in (0, 4, 5, 8, 12, 14):
        raise ValueError(f"OpenCV takes 4, 5, 8, 12 or 14 distortion coefficients, got {d.size}")
    out = np.zeros(14)
    out[: d.size] = d
    return out


def tilt_matrix(tau_x: float, tau_y: float) -> np.ndarray:
    """``(3, 3)`` tilted-sensor homography of OpenCV's 14-coefficient model (angles in radians)."""
    cx, sx, cy, sy = np.cos(tau_x), np.sin(tau_x), np.cos(tau_y), np.sin(tau_y)
    rot_x = np.array([[1.0, 0.0, 0.0], [0.0, cx, sx], [0.0, -sx, cx]])
    rot_y = np.array([[cy, 0.0, -sy], [0.0, 1.0, 0.0], [sy, 0.0, cy]])
    rot_xy = rot_y @ rot_x
    proj_z = np.array([[rot_xy[2, 2], 0.0, -rot_xy[0, 2]], [0.0, rot_xy[2, 2], -rot_xy[1, 2]], [0.0, 0.0, 1.0]])
    return proj_z @ rot_xy


def project_camera_points(
    P: np.ndarray, K: np.ndarray, dist: np.ndarray | list[float], *, jacobian: bool = False
) -> tuple[np.ndarray, np.ndarray | None]:
    """Project ``(n, 3)`` camera-frame points (metres) to ``(n, 2)`` pixels with OpenCV's model.

    With ``jacobian=True`` also returns ``(n, 2, 3)``: d(pixel)/d(point), pixels
    per metre; otherwise ``None`` in its place.
    """
    P = np.asarray(P, dtype=np.float64)
    d = dist14(dist)
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4, tau_x, tau_y = d
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    X, Y, Z = P[:, 0], P[:, 1], P[:, 2]
    iz = np.divide(1.0, Z, out=np.ones_like(Z), where=Z != 0)
    x, y = X * iz, Y * iz
    r2 = x * x + y * y
    r4 = r2 * r2
    r6 = r4 * r2
    num = 1.0 + k1 * r2 + k2 * r4 + k3 * r6
    den = 1.0 + k4 * r2 + k5 * r4 + k6 * r6
    iden = 1.0 / den
    radial = num * iden
    xy = x * y
    xd = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x) + s1 * r2 + s2 * r4
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy + s3 * r2 + s4 * r4
    tilted = tau_x != 0.0 or tau_y != 0.0
    if tilted:
        M = tilt_matrix(tau_x, tau_y)
        w = M[2, 0] * xd + M[2, 1] * yd + M[2, 2]
        iw = np.divide(1.0, w, out=np.ones_like(w), where=w != 0)
        xt = (M[0, 0] * xd + M[0, 1] * yd + M[0, 2]) * iw
        yt = (M[1, 0] * xd + M[1, 1] * yd + M[1, 2]) * iw
    else:
        xt, yt = xd, yd
    uv = np.stack([fx * xt + cx, fy * yt + cy], axis=1)
    if not jacobian:
        return uv, None
    # d(radial)/d(r2), then d(xd, yd)/d(x, y) by the chain rule through r2.
    dnum = k1 + 2.0 * k2 * r2 + 3.0 * k3 * r4
    dden = k4 + 2.0 * k5 * r2 + 3.0 * k6 * r4
    dradial = (dnum - radial * dden) * iden
    dxd_dr2 = x * dradial + p2 + s1 + 2.0 * s2 * r2
    dyd_dr2 = y * dradial + p1 + s3 + 2.0 * s4 * r2
    J_d = np.empty((P.shape[0], 2, 2))
    J_d[:, 0, 0] = radial + 2.0 * p1 * y + 4.0 * p2 * x + dxd_dr2 * 2.0 * x
    J_d[:, 0, 1] = 2.0 * p1 * x + dxd_dr2 * 2.0 * y
    J_d[:, 1, 0] = 2.0 * p2 * y + dyd_dr2 * 2.0 * x
    J_d[:, 1, 1] = radial + 4.0 * p1 * y + 2.0 * p2 * x + dyd_dr2 * 2.0 * y
    if tilted:
        # Quotient rule of the homography: d(a / w) = (da - (a / w) dw) / w.
        J_t = np.empty_like(J_d)
        J_t[:, 0, 0] = (M[0, 0] - xt * M[2, 0]) * iw
        J_t[:, 0, 1] = (M[0, 1] - xt * M[2, 1]) * iw
        J_t[:, 1, 0] = (M[1, 0] - yt * M[2, 0]) * iw
        J_t[:, 1, 1] = (M[1, 1] - yt * M[2, 1]) * iw
        J_d = J_t @ J_d
    # d(x, y)/d(X, Y, Z) of the perspective division.
    J_p = np.zeros((P.shape[0], 2, 3))
    J_p[:, 0, 0] = iz
    J_p[:, 0, 2] = -x * iz
    J_p[:, 1, 1] = iz
    J_p[:, 1, 2] = -y * iz
    J = J_d @ J_p
    J[:, 0, :] *= fx
    J[:, 1, :] *= fy
    return uv, J


def rotation_matrices(rvecs: np.ndarray) -> np.ndarray:
    """``(m, 3, 3)`` rotation matrices of ``(m, 3)`` rotation vectors (radians)."""
    return Rotation.from_rotvec(np.asarray(rvecs, dtype=np.float64).reshape(-1, 3)).as_matrix()


def skew(v: np.ndarray) -> np.ndarray:
    """``(m, 3, 3)`` cross-product matrices ``[v]x`` of ``(m, 3)`` vectors."""
    v = np.asarray(v, dtype=np.float64).reshape(-1, 3)
    S = np.zeros((v.shape[0], 3, 3))
    S[:, 0, 1], S[:, 0, 2] = -v[:, 2], v[:, 1]
    S[:, 1, 0], S[:, 1, 2] = v[:, 2], -v[:, 0]
    S[:, 2, 0], S[:, 2, 1] = -v[:, 1], v[:, 0]
    return S


def so3_left_jacobian(rvecs: np.ndarray) -> np.ndarray:
    """``(m, 3, 3)`` left Jacobians of SO(3) at ``(m, 3)`` rotation vectors (radians).

    ``J_l(r) = I + (1 - cos t) / t^2 [r]x + (t - sin t) / t^3 [r]x^2`` with
    ``t = |r|``; Taylor series below 1e-4 rad where the quotients lose digits.
    """
    r = np.asarray(rvecs, dtype=np.float64).reshape(-1, 3)
    t2 = np.sum(r * r, axis=1)
    t = np.sqrt(t2)
    small = t < 1e-4
    ts = np.where(small, 1.0, t)
    a = np.where(small, 0.5 - t2 / 24.0, (1.0 - np.cos(ts)) / ts**2)
    b = np.where(small, 1.0 / 6.0 - t2 / 120.0, (ts - np.sin(ts)) / ts**3)
    S = skew(r)
    return np.eye(3) + a[:, None, None] * S + b[:, None, None] * (S @ S)
