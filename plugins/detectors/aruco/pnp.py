"""Pose of one part from all corners of all its visible markers (camera frame, metres).

One PnP over every corner of every visible marker of the part, never an
average of per-marker poses. Initial guesses come from both IPPE solutions of
each marker (a single planar square has two poses that fit almost equally
well: the "flip"); each guess is scored on all the part's corners, the best
few are refined with Levenberg-Marquardt, and markers whose reprojection error
stands out are rejected. When the two best refined poses fit about equally
well, the runner-up is kept as an alternative for the fusion over frames to
decide.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from asmteach.core import geometry
from asmteach.plugins.detectors.aruco.markers import corner_offsets

__all__ = ["MarkerObservation", "PartPose", "project", "solve_part_pose"]


@dataclass(frozen=True)
class MarkerObservation:
    """One detected marker of a part: its spec's pose and size, and its image corners."""

    marker_id: int
    size: float
    T_part_marker: np.ndarray
    corners_px: np.ndarray
    """``(4, 2)`` detected corners, OpenCV's order, pixels."""

    @property
    def object_points(self) -> np.ndarray:
        """``(4, 3)`` corners in the part frame, metres."""
        c = corner_offsets(self.size)
        return c @ self.T_part_marker[:3, :3].T + self.T_part_marker[:3, 3]


@dataclass
class PartPose:
    """Result of :func:`solve_part_pose`: ``T_cam_part`` and how well it fits."""

    T_cam_part: np.ndarray
    rms_px: float
    marker_ids: list[int]
    marker_rms_px: list[float]
    rejected_ids: list[int] = field(default_factory=list)
    alternatives: list[tuple[np.ndarray, float]] = field(default_factory=list)
    """Other poses fitting almost as well (flip ambiguity): ``(T_cam_part, rms_px)``."""


def _to_T(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    return geometry.from_rotation(R, np.asarray(tvec, dtype=np.float64).ravel())


def _to_rt(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rvec, _ = cv2.Rodrigues(np.ascontiguousarray(T[:3, :3]))
    return rvec, np.ascontiguousarray(T[:3, 3]).reshape(3, 1)


def project(T_cam_obj: np.ndarray, points: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Project ``(n, 3)`` object points with pose ``T_cam_obj``; returns ``(n, 2)`` pixels."""
    rvec, tvec = _to_rt(T_cam_obj)
    out, _ = cv2.projectPoints(np.ascontiguousarray(points, dtype=np.float64), rvec, tvec, K, dist)
    return out.reshape(-1, 2)


def _residuals(T: np.ndarray, obj: np.ndarray, img: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Per-point reprojection error (pixels); +inf for points behind the camera."""
    cam = geometry.transform_points(T, obj)
    err = np.linalg.norm(project(T, obj, K, dist) - img, axis=1)
    err[cam[:, 2] <= 1e-6] = np.inf
    return err


def _refine(T: np.ndarray, obj: np.ndarray, img: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    rvec, tvec = _to_rt(T)
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-12)
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, dist, rvec, tvec, criteria)
    return _to_T(rvec, tvec)


def _rms(err: np.ndarray) -> float:
    return float(np.sqrt(np.mean(err**2)))


def solve_part_pose(
    observations: list[MarkerObservation],
    K: np.ndarray,
    dist: np.ndarray,
    *,
    priors: list[np.ndarray] | None = None,
    reject_px: float = 2.0,
    ambiguity_ratio: float = 1.5,
) -> PartPose | None:
    """Multi-marker PnP of one part; ``None`` when no pose fits.

    Parameters
    ----------
    observations : the part's markers detected in one frame (at least one).
    K, dist : camera matrix and OpenCV distortion coefficients.
    priors : extra initial guesses ``T_cam_part`` (e.g. the previous frame's pose).
    reject_px : a marker whose RMS error exceeds this and three times the
        median of the others is dropped (only while two or more remain).
    ambiguity_ratio : a distinct pose (> 5 deg away) whose RMS is within this
        factor of the best is kept as an alternative.
    """
    obs = list(observations)
    rejected: list[int] = []
    K = np.asarray(K, dtype=np.float64)
    dist = np.asarray(dist, dtype=np.float64).ravel()
    while obs:
        obj = np.concatenate([o.object_points for o in obs]).astype(np.float64)
        img = np.concatenate([o.corners_px for o in obs]).astype(np.float64)
        guesses: list[np.ndarray] = [np.asarray(p, dtype=float) for p in (priors or [])]
        for o in obs:
            n, rvecs, tvecs, _ = cv2.solvePnPGeneric(
                corner_offsets(o.size), o.corners_px, K, dist, flags=cv2.SOLVEPNP_IPPE_SQUARE
            )
            T_marker_part = geometry.invert(o.T_part_marker)
            guesses += [_to_T(r, t) @ T_marker_part for r, t in zip(rvecs[:n], tvecs[:n], strict=True)]
        scored = sorted(((_rms(_residuals(T, obj, img, K, dist)), i) for i, T in enumerate(guesses)))
        # Refine the best few distinct guesses on all corners, then rank again.
        refined: list[tuple[float, np.ndarray]] = []
        for score, i in scored[:4]:
            if not np.isfinite(score):
                continue
            T = _refine(guesses[i], obj, img, K, dist)
            refined.append((_rms(_residuals(T, obj, img, K, dist)), T))
        if not refined:
            return None
        refined.sort(key=lambda x: x[0])
        best_rms, best = refined[0]
        if not np.isfinite(best_rms):
            return None
        per_marker = _residuals(best, obj, img, K, dist).reshape(len(obs), 4)
        marker_rms = np.sqrt(np.mean(per_marker**2, axis=1))
        worst = int(np.argmax(marker_rms))
        if len(obs) >= 2:
            others = np.delete(marker_rms, worst)
            if marker_rms[worst] > max(reject_px, 3.0 * float(np.median(others))):
                rejected.append(obs[worst].marker_id)
                obs.pop(worst)
                continue
        elif marker_rms[0] > reject_px:
            rejected.append(obs[0].marker_id)
            return None
        alternatives = []
        for r, T in refined[1:]:
            if r <= ambiguity_ratio * max(best_rms, 0.05) and geometry.rotation_distance(T, best) > np.radians(5.0):
                if all(geometry.rotation_distance(T, a) > np.radians(5.0) for a, _ in alternatives):
                    alternatives.append((T, r))
        return PartPose(
            T_cam_part=best,
            rms_px=best_rms,
            marker_ids=[o.marker_id for o in obs],
            marker_rms_px=[float(x) for x in marker_rms],
            rejected_ids=rejected,
            alternatives=alternatives,
        )
    return None
