"""The planar-flip branch of a part's pose, chosen over all frames from how the part moves (issue 23).

A part seen through one square marker has two poses that fit its four
corners almost equally well (IPPE's two solutions: the marker tilted toward or
away from the camera). In a single frame the wrong one often fits a little
better, by noise. A hand moves the part smoothly, so the true poses follow one
smooth track through the frames while picking the better-fitting pose frame by
frame jumps between the tracks. :func:`track_branches` picks one candidate
per frame minimising, over the whole sequence (Viterbi),

    sum_k  n_k rms_k^2 / sigma^2  +  sum_k  (angle(R_k-1, R_k) / (step * gap_k))^2

the corners' misfit (``n_k`` corners, ``rms_k`` pixels, ``sigma`` the corner
noise) plus the rotation change between consecutive frames where the part is
seen (``gap_k`` frames apart) against the typical per-frame ``step``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from asmteach.core import geometry
from asmteach.plugins.detectors.aruco.pnp import PartPose

__all__ = ["Candidate", "follow_branch", "track_branches"]

Candidate = tuple[np.ndarray, float, int]
"""``(T_cam_part, rms_px, corners)``: one pose a frame allows, its RMS reprojection error and corner count."""


def track_branches(
    frames: Sequence[Sequence[Candidate] | None], *, sigma_px: float | None = None, step_rad: float | None = None
) -> list[int | None]:
    """Index of the chosen candidate in every frame (``None`` where the part is not seen).

    ``sigma_px`` defaults to the median best RMS over the frames (at least
    0.02 px); ``step_rad`` to the median rotation change between consecutive
    frames' first candidates (at least 0.2 deg): the typical motion, measured
    on the poses themselves.
    """
    seen = [k for k, c in enumerate(frames) if c]
    cands: list[list[Candidate]] = [list(frames[k] or ()) for k in seen]
    out: list[int | None] = [None] * len(frames)
    if not seen:
        return out
    if sigma_px is None:
        sigma_px = max(float(np.median([min(c[1] for c in cs) for cs in cands])), 0.02)
    if step_rad is None:
        steps = [
            geometry.rotation_distance(cands[i][0][0], cands[i + 1][0][0]) / (seen[i + 1] - seen[i])
            for i in range(len(seen) - 1)
        ]
        step_rad = max(float(np.median(steps)) if steps else 0.0, np.radians(0.2))
    sigma2 = sigma_px**2

    def data(cs: list[Candidate]) -> np.ndarray:
        return np.array([n * rms**2 / sigma2 for _, rms, n in cs])

    cost = data(cands[0])
    back: list[np.ndarray] = []
    for i in range(1, len(seen)):
        scale = step_rad * (seen[i] - seen[i - 1])
        trans = np.array(
            [[(geometry.rotation_distance(p[0], c[0]) / scale) ** 2 for c in cands[i]] for p in cands[i - 1]]
        )
        total = cost[:, None] + trans
        back.append(np.argmin(total, axis=0))
        cost = total.min(axis=0) + data(cands[i])
    j = int(np.argmin(cost))
    for i in range(len(seen) - 1, -1, -1):
        out[seen[i]] = j
        if i > 0:
            j = int(back[i - 1][j])
    return out


def follow_branch(poses: list[PartPose | None]) -> None:
    """Put each frame's pose on the flip branch the part's motion follows (:func:`track_branches`), in place.

    A pose whose alternative the track picks swaps the two: the alternative
    becomes the pose, the old pose an alternative (``marker_rms_px`` stays
    the old pose's: the alternative's per-marker errors are not kept).
    """
    cands = [
        None
        if p is None
        else [(p.T_cam_part, p.rms_px, 4 * len(p.marker_ids))]
        + [(T, r, 4 * len(p.marker_ids)) for T, r in p.alternatives]
        for p in poses
    ]
    for p, j in zip(poses, track_branches(cands), strict=True):
        if p is None or not j:
            continue
        T, r = p.alternatives[j - 1]
        p.alternatives[j - 1] = (p.T_cam_part, p.rms_px)
        p.T_cam_part, p.rms_px = T, r
