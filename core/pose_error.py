"""How far an estimated pose is from a reference: the one vocabulary of pose errors.

Every stage, experiment and report states a pose error with these names:

- ``position_mm``: distance between the two origins, millimetres;
- ``angle_deg``: geodesic angle of ``R_est^T R_ref`` on SO(3), degrees, in [0, 180];
- ``dxyz_mm``: estimate minus reference, origin to origin, in the frame both poses
  are expressed in (the world for ``T_world_part``), millimetres;
- ``drpy_deg``: roll, pitch, yaw (degrees) of ``R_est R_ref^T``, the rotation that
  takes the reference onto the estimate, in that same frame.

Parts with symmetries: poses that put the same solid in the same place are the
same answer. :func:`pose_error` takes the part's symmetries (part-frame
transforms from :func:`asmteach.core.symmetry.part_symmetries`) and measures
against the nearest equivalent reference, nearest by ``position_mm + angle_deg``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from asmteach.core import geometry

__all__ = ["PoseError", "nearest_symmetric", "pose_error"]


@dataclass(frozen=True)
class PoseError:
    """The error of one pose against one reference (see the module's vocabulary)."""

    position_mm: float
    angle_deg: float
    dxyz_mm: tuple[float, float, float]
    drpy_deg: tuple[float, float, float]

    def as_dict(self) -> dict[str, float | list[float]]:
        """JSON form, with the vocabulary's names."""
        return {
            "position_mm": self.position_mm,
            "angle_deg": self.angle_deg,
            "dxyz_mm": list(self.dxyz_mm),
            "drpy_deg": list(self.drpy_deg),
        }

    def short(self, digits: int | None = None) -> dict[str, float]:
        """``{"position_mm", "angle_deg"}``, rounded to ``digits`` when given: the form reports keep."""
        pos, ang = self.position_mm, self.angle_deg
        if digits is not None:
            pos, ang = round(pos, digits), round(ang, digits)
        return {"position_mm": pos, "angle_deg": ang}

    def within(self, position_mm: float, angle_deg: float) -> bool:
        """Both errors at or under the given limits (mm, deg)."""
        return self.position_mm <= position_mm and self.angle_deg <= angle_deg


def _equivalents(T_ref: np.ndarray, left: Sequence[np.ndarray], right: Sequence[np.ndarray]) -> np.ndarray:
    """``inv(S_l) @ T_ref @ S_r`` for every pair, ``(m, 4, 4)``."""
    L = np.linalg.inv(np.asarray(left, dtype=float).reshape(-1, 4, 4)) if len(left) else np.eye(4)[None]
    R = np.asarray(right, dtype=float).reshape(-1, 4, 4) if len(right) else np.eye(4)[None]
    return np.einsum("aij,jk,bkl->abil", L, T_ref, R).reshape(-1, 4, 4)


def _nearest(T: np.ndarray, candidates: np.ndarray) -> int:
    """Index of the candidate ``(m, 4, 4)`` nearest ``T`` by millimetres + degrees (geodesic)."""
    pos = 1000.0 * np.linalg.norm(candidates[:, :3, 3] - T[:3, 3], axis=1)
    cos = (np.einsum("ij,sij->s", T[:3, :3], candidates[:, :3, :3]) - 1.0) / 2.0
    return int(np.argmin(pos + np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))))


def pose_error(
    T_est: np.ndarray,
    T_ref: np.ndarray,
    left: Sequence[np.ndarray] = (),
    right: Sequence[np.ndarray] = (),
) -> PoseError:
    """Error of ``T_est`` against the nearest of ``inv(S_l) @ T_ref @ S_r`` (4x4, metres).

    ``right`` holds the symmetries of the estimated part (part-frame transforms):
    ``T_ref @ S_r`` is the same solid in the same place. ``left`` holds those of
    the frame ``T_ref`` is expressed in (the other part's, for a relative pose
    ``T_A_B``, or world-frame turns such as a placement's symmetry yaws).
    With neither, the plain error.
    """
    T_est = np.asarray(T_est, dtype=float)
    eq = _equivalents(np.asarray(T_ref, dtype=float), left, right)
    ref = eq[_nearest(T_est, eq)]
    d = 1000.0 * (T_est[:3, 3] - ref[:3, 3])
    # The angle from the trace loses precision near 0; the rotation vector does not.
    angle = float(np.degrees(geometry.rotation_distance(T_est, ref)))
    drpy = np.degrees(geometry.rpy(T_est[:3, :3] @ ref[:3, :3].T))
    return PoseError(
        position_mm=float(np.linalg.norm(d)),
        angle_deg=angle,
        dxyz_mm=(float(d[0]), float(d[1]), float(d[2])),
        drpy_deg=(float(drpy[0]), float(drpy[1]), float(drpy[2])),
    )


def nearest_symmetric(T: np.ndarray, T_ref: np.ndarray, symmetries: Sequence[np.ndarray]) -> np.ndarray:
    """Of the poses ``T @ S`` that put the same solid in the same place, the one nearest ``T_ref``."""
    T = np.asarray(T, dtype=float)
    if not len(symmetries):
        return T
    candidates = np.einsum("ij,sjk->sik", T, np.asarray(symmetries, dtype=float).reshape(-1, 4, 4))
    return candidates[_nearest(np.asarray(T_ref, dtype=float), candidates)]
