"""Robust averaging of rigid transforms over frames (rotation and translation, outlier rejection)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from asmteach.core import geometry

__all__ = ["FusedPose", "fuse_poses"]

_MAD_TO_STD = 1.4826


@dataclass
class FusedPose:
    """A fused transform, which inputs it kept, and their spread about it."""

    T: np.ndarray
    inliers: np.ndarray
    """``(n,) bool`` inputs kept."""
    spread_m: float
    """RMS distance of the kept translations from the fused one, metres."""
    spread_rad: float
    """RMS geodesic angle of the kept rotations from the fused one, radians."""


def _mean(Ts: np.ndarray, w: np.ndarray) -> np.ndarray:
    # scipy's Rotation.mean is the chordal L2 mean (weighted quaternion eigenvector).
    R = Rotation.from_matrix(Ts[:, :3, :3]).mean(weights=w).as_matrix()
    t = (w[:, None] * Ts[:, :3, 3]).sum(axis=0) / w.sum()
    return geometry.from_rotation(R, t)


def fuse_poses(
    Ts: np.ndarray,
    weights: np.ndarray | None = None,
    *,
    k: float = 3.0,
    min_trans: float = 2e-4,
    min_rot: float = np.radians(0.2),
    iterations: int = 5,
) -> FusedPose:
    """Robust mean of ``(n, 4, 4)`` transforms.

    Starts from the geometric medians' neighbourhood (component-wise median
    translation, the rotation whose summed distance to the rest is least), then
    alternates a weighted mean of the inliers with rejection of inputs further
    than ``k`` robust standard deviations (MAD) in translation or rotation.
    ``min_trans`` (metres) and ``min_rot`` (radians) floor the rejection radii
    so near-identical inputs are not trimmed by a vanishing MAD.
    """
    Ts = np.asarray(Ts, dtype=float).reshape(-1, 4, 4)
    n = len(Ts)
    if n == 0:
        raise ValueError("fuse_poses needs at least one transform")
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=float)
    rots = Rotation.from_matrix(Ts[:, :3, :3])
    if n <= 2:
        T = _mean(Ts, w)
        inl = np.ones(n, dtype=bool)
    else:
        # Medoid rotation: robust start that a flipped minority cannot drag.
        sub = np.arange(n) if n <= 200 else np.linspace(0, n - 1, 200).astype(int)
        d = np.array([(rots[sub].inv() * rots[i]).magnitude().sum() for i in range(n)])
        T = geometry.from_rotation(rots[int(np.argmin(d))].as_matrix(), np.median(Ts[:, :3, 3], axis=0))
        inl = np.ones(n, dtype=bool)
        for _ in range(iterations):
            dt = np.linalg.norm(Ts[:, :3, 3] - T[:3, 3], axis=1)
            dr = (Rotation.from_matrix(T[:3, :3]).inv() * rots).magnitude()
            st = max(_MAD_TO_STD * float(np.median(dt)), min_trans / k)
            sr = max(_MAD_TO_STD * float(np.median(dr)), min_rot / k)
            new = (dt <= k * st) & (dr <= k * sr)
            if not new.any():
                break
            T = _mean(Ts[new], w[new])
            if np.array_equal(new, inl):
                break
            inl = new
        inl = inl if inl.any() else np.ones(n, dtype=bool)
    dt = np.linalg.norm(Ts[inl, :3, 3] - T[:3, 3], axis=1)
    dr = (Rotation.from_matrix(T[:3, :3]).inv() * rots[inl]).magnitude()
    return FusedPose(
        T=T,
        inliers=inl,
        spread_m=float(np.sqrt(np.mean(dt**2))),
        spread_rad=float(np.sqrt(np.mean(dr**2))),
    )
