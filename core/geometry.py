"""Rigid transforms as 4x4 homogeneous matrices.

Conventions used everywhere in asmteach:

* A pose is a ``(4, 4) float`` numpy array ``T_a_b`` that maps coordinates in
  frame ``b`` into frame ``a`` (``p_a = T_a_b @ p_b``). Translations are in
  metres, angles in radians. Millimetres and degrees appear only in reports.
* ``rpy`` is fixed-axis roll about x, then pitch about y, then yaw about z,
  i.e. ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (the URDF convention).
* Quaternions are ``(x, y, z, w)`` (scipy's and PyBullet's order).

scipy's :class:`~scipy.spatial.transform.Rotation` does the rotation algebra;
nothing here re-derives it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

__all__ = [
    "as_transform",
    "compose",
    "cross",
    "from_quat",
    "from_rotvec",
    "from_rpy",
    "from_xyz_rpy",
    "invert",
    "rot_z",
    "rotation_angle",
    "rotation_distance",
    "rpy",
    "to_quat",
    "to_xyz_mm_rpy_deg",
    "transform_points",
    "translation_distance",
    "yaw_of",
]


def as_transform(T: ArrayLike) -> np.ndarray:
    """Return ``T`` as a validated ``(4, 4) float`` rigid transform.

    Raises ``ValueError`` when the shape is wrong, the last row is not
    ``[0, 0, 0, 1]`` or the rotation block is not orthonormal (tolerance 1e-5).
    """
    M = np.asarray(T, dtype=float)
    if M.shape != (4, 4):
        raise ValueError(f"a pose must be a 4x4 matrix, got shape {M.shape}")
    if not np.allclose(M[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise ValueError(f"the last row of a pose must be [0, 0, 0, 1], got {M[3].tolist()}")
    R = M[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-5) or np.linalg.det(R) < 0:
        raise ValueError("the rotation block of a pose is not a proper rotation matrix")
    return M


def from_rotation(R: ArrayLike, t: ArrayLike = (0.0, 0.0, 0.0)) -> np.ndarray:
    """``(4, 4)`` transform from a ``(3, 3)`` rotation and a translation (metres)."""
    T = np.eye(4)
    T[:3, :3] = np.asarray(R, dtype=float)
    T[:3, 3] = np.asarray(t, dtype=float)
    return T


def from_rpy(roll: float, pitch: float, yaw: float, t: ArrayLike = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Transform from fixed-axis roll, pitch, yaw (radians) and a translation (metres)."""
    R = Rotation.from_euler("xyz", [roll, pitch, yaw]).as_matrix()
    return from_rotation(R, t)


def from_xyz_rpy(xyz: Sequence[float], rpy_rad: Sequence[float]) -> np.ndarray:
    """Transform from ``xyz`` (metres) and ``rpy`` (radians)."""
    return from_rpy(*rpy_rad, t=xyz)


def from_quat(q_xyzw: ArrayLike, t: ArrayLike = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Transform from a quaternion ``(x, y, z, w)`` and a translation (metres)."""
    return from_rotation(Rotation.from_quat(q_xyzw).as_matrix(), t)


def from_rotvec(rotvec: ArrayLike, t: ArrayLike = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Transform from a rotation vector (axis * angle, radians) and a translation."""
    return from_rotation(Rotation.from_rotvec(rotvec).as_matrix(), t)


def rot_z(yaw: float) -> np.ndarray:
    """``(4, 4)`` pure rotation about the z axis by ``yaw`` radians."""
    return from_rpy(0.0, 0.0, yaw)


def rpy(T: ArrayLike) -> np.ndarray:
    """Fixed-axis ``(roll, pitch, yaw)`` in radians of a transform or a 3x3 rotation."""
    M = np.asarray(T, dtype=float)
    return Rotation.from_matrix(M[:3, :3]).as_euler("xyz")


def yaw_of(T: ArrayLike) -> float:
    """Yaw (radians) of the rotation, in the fixed-axis rpy convention."""
    return float(rpy(T)[2])


def to_quat(T: ArrayLike) -> np.ndarray:
    """Quaternion ``(x, y, z, w)`` of a transform or a rotation matrix."""
    return Rotation.from_matrix(np.asarray(T, dtype=float)[:3, :3]).as_quat()


def invert(T: ArrayLike) -> np.ndarray:
    """Inverse of a rigid transform (closed form, no general matrix inverse)."""
    M = np.asarray(T, dtype=float)
    out = np.eye(4)
    out[:3, :3] = M[:3, :3].T
    out[:3, 3] = -M[:3, :3].T @ M[:3, 3]
    return out


def compose(*Ts: ArrayLike) -> np.ndarray:
    """Product ``T0 @ T1 @ ...`` of transforms."""
    out = np.eye(4)
    for T in Ts:
        out = out @ np.asarray(T, dtype=float)
    return out


def transform_points(T: ArrayLike, points: ArrayLike) -> np.ndarray:
    """Apply ``T`` to ``(n, 3)`` points; returns ``(n, 3)``."""
    M = np.asarray(T, dtype=float)
    P = np.asarray(points, dtype=float).reshape(-1, 3)
    return P @ M[:3, :3].T + M[:3, 3]


def rotation_angle(R: ArrayLike) -> float:
    """Angle (radians, in [0, pi]) of a rotation given as 3x3 or 4x4."""
    M = np.asarray(R, dtype=float)[:3, :3]
    return float(Rotation.from_matrix(M).magnitude())


def rotation_distance(A: ArrayLike, B: ArrayLike) -> float:
    """Geodesic distance on SO(3), ``|log(A^T B)|`` in radians."""
    Ra = np.asarray(A, dtype=float)[:3, :3]
    Rb = np.asarray(B, dtype=float)[:3, :3]
    return rotation_angle(Ra.T @ Rb)


def translation_distance(A: ArrayLike, B: ArrayLike) -> float:
    """Euclidean distance (metres) between the origins of two transforms."""
    return float(np.linalg.norm(np.asarray(A, float)[:3, 3] - np.asarray(B, float)[:3, 3]))


def to_xyz_mm_rpy_deg(T: ArrayLike) -> dict[str, list[float]]:
    """Report form of a pose: ``{"xyz_mm": [...], "rpy_deg": [...]}``."""
    M = np.asarray(T, dtype=float)
    return {
        "xyz_mm": (M[:3, 3] * 1000.0).round(4).tolist(),
        "rpy_deg": np.degrees(rpy(M)).round(4).tolist(),
    }


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of ``(..., 3)`` arrays.

    The same as :func:`numpy.cross`, whose axis handling costs tens of
    microseconds per call: more than the arithmetic on a small hull.
    """
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)
