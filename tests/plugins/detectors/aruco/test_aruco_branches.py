"""Flip branches followed over frames (:mod:`asmteach.plugins.detectors.aruco.branches`)."""

from __future__ import annotations

import numpy as np

from asmteach.core import geometry
from asmteach.plugins.detectors.aruco.branches import follow_branch, track_branches
from asmteach.plugins.detectors.aruco.pnp import PartPose


def _tracks(n: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """A smoothly turning part (0.5 deg per frame) and its flip: tilted 8 deg the other way, as IPPE's twin."""
    true, flip = [], []
    for k in range(n):
        R = geometry.from_rotvec(np.radians([0.5 * k, 0.2 * k, 0.0]), np.array([0.0, 0.0, 0.45]))
        true.append(R)
        flip.append(R @ geometry.from_rotvec(np.radians([8.0 + 3.0 * np.sin(k), 0.0, 0.0]), np.zeros(3)))
    return true, flip


def test_the_track_follows_the_smooth_branch_where_single_frames_prefer_the_flip() -> None:
    rng = np.random.default_rng(3)
    true, flip = _tracks(20)
    # Per frame the flip fits better in about half the frames (noise), by a little; the true branch fits better
    # on average, as it does on real corners.
    rms_true = 0.05 + 0.01 * rng.random(20)
    rms_flip = rms_true + rng.normal(0.003, 0.006, 20)
    frames = [[(true[k], rms_true[k], 4), (flip[k], rms_flip[k], 4)] for k in range(20)]
    frames[7] = None  # the part not seen in one frame
    per_frame = [None if f is None else int(np.argmin([c[1] for c in f])) for f in frames]
    assert sum(j == 1 for j in per_frame) >= 5  # frame by frame, the flip wins often
    chosen = track_branches(frames)
    assert chosen[7] is None
    assert all(j == 0 for k, j in enumerate(chosen) if k != 7)
    # Listed the other way round, the same track is found.
    swapped = [None if f is None else [f[1], f[0]] for f in frames]
    assert all(j == 1 for k, j in enumerate(track_branches(swapped)) if k != 7)


def test_follow_branch_swaps_a_pose_with_its_alternative_in_place() -> None:
    true, flip = _tracks(6)
    poses: list[PartPose | None] = []
    for k in range(6):
        # Frame 2 solved to the flip (it fitted marginally better there); the others to the true pose.
        best, alt = (flip[k], true[k]) if k == 2 else (true[k], flip[k])
        poses.append(PartPose(best, 0.05, [3], [0.05], alternatives=[(alt, 0.052)]))
    follow_branch(poses)
    for k, p in enumerate(poses):
        assert p is not None
        assert geometry.rotation_distance(p.T_cam_part, true[k]) < 1e-9
        assert geometry.rotation_distance(p.alternatives[0][0], flip[k]) < 1e-9
    assert poses[2] is not None and poses[2].rms_px == 0.052
