"""The demonstration renderer's anti-aliasing does not bias marker corners (issue 23, one marker per part).

A regular ``S x S`` sample grid quantises an edge lying near a pixel axis to
``1 / S`` pixel, the same step along the whole edge: at 4 x 4 the edge-fitted
corners were off by 0.07 px RMS, which tilts a single small marker's pose by
degrees. Jittered samples leave only noise that averages out along the edge.
"""

from __future__ import annotations

import cv2
import numpy as np
import trimesh

from asmteach.core import geometry
from asmteach.core.models import MarkerSpec
from asmteach.plugins.detectors.aruco.camera import c615_like
from asmteach.plugins.detectors.aruco.detect import MarkerDetector
from asmteach.plugins.detectors.aruco.markers import marker_bits, marker_corners_part
from asmteach.plugins.detectors.aruco.pnp import project
from asmteach.plugins.detectors.aruco.raycast import INK_BLACK, PAPER_WHITE
from asmteach.plugins.detectors.aruco.render import RenderObject, render_scene


def _corner_errors(shifts_px: np.ndarray, roll_deg: float) -> np.ndarray:
    """Detected minus true corners (pixels) of a 20 mm marker 0.45 m away, square-on, rolled ``roll_deg``."""
    cam = c615_like()
    f = cam.K[0, 0]
    marker = MarkerSpec(dictionary="DICT_4X4_50", id=7, size=0.02, T_part_marker=np.eye(4))
    slab = trimesh.creation.box(extents=(0.03, 0.03, 0.004))
    slab.apply_translation((0.0, 0.0, -0.002))  # top face at z = 0, where the marker lies
    det = MarkerDetector(["DICT_4X4_50"])
    errs = []
    for dx, dy in shifts_px:
        # Marker z toward the camera (camera z forward): a half turn about x, then the roll about the view axis.
        R = (
            geometry.from_rotvec(np.array([0.0, 0.0, np.radians(roll_deg)]), np.zeros(3))[:3, :3]
            @ geometry.from_rotvec(np.array([np.pi, 0.0, 0.0]), np.zeros(3))[:3, :3]
        )
        z = 0.45
        T = geometry.from_rotation(R, np.array([dx * z / f, dy * z / f, z]))
        r = render_scene(
            [RenderObject(slab, (0.6, 0.6, 0.6), [marker], T)],
            cam.K,
            cam.width,
            cam.height,
            background=np.full((cam.height, cam.width, 3), 0.4, np.float32),
            supersample=4,
        )
        img = (np.clip(r.image, 0, 1) * 255 + 0.5).astype(np.uint8)[..., ::-1]
        found = det.detect(img)
        if ("DICT_4X4_50", 7) in found:
            errs.append(found[("DICT_4X4_50", 7)] - project(T, marker_corners_part(marker), cam.K, cam.dist_array))
    # On noise-free renders the edge refinement's outlier cut refuses about one marker in 25 whatever the jitter
    # (5 of 144 renders of this scene over 24 jitter seeds, 8 of 144 with the session-14 jitter): at most one miss.
    assert len(errs) >= len(shifts_px) - 1, f"{len(errs)} of {len(shifts_px)} detected"
    return np.concatenate(errs)


def test_corners_of_a_marker_near_the_pixel_axes_are_unbiased() -> None:
    # Edges 0.5 deg off the pixel rows and columns, at sub-pixel offsets spread over one pixel.
    shifts = np.array([(0.1 + 0.37 * k, 0.05 + 0.23 * k) for k in range(6)])
    e = _corner_errors(shifts, roll_deg=0.5)
    rms = float(np.sqrt(np.mean(e**2)))
    # Sample-centred 4 x 4 grid (the old renderer): 0.078 px RMS, worst 0.18 px. Jittered: 0.020, worst 0.055.
    assert rms < 0.04, rms
    assert float(np.abs(e).max()) < 0.1


def _warp_render(marker: MarkerSpec, T_cam_marker: np.ndarray, K: np.ndarray, w: int, h: int) -> np.ndarray:
    """An independent renderer: the marker (one-cell quiet zone) as a plane homography ``K [r1 r2 t]`` applied by
    ``cv2.warpPerspective`` to a 40 px/cell texture (nearest texel), 8 x 8 supersampled and box-filtered."""
    S, per_cell = 8, 40
    bits = marker_bits(marker)
    n = bits.shape[0]
    tex = np.full(((n + 2) * per_cell,) * 2, PAPER_WHITE, np.float32)
    tex[per_cell:-per_cell, per_cell:-per_cell] = np.where(
        np.kron(bits, np.ones((per_cell, per_cell), bool)), INK_BLACK, PAPER_WHITE
    )
    N = tex.shape[0]
    half = 0.5 * marker.size * (n + 2) / n
    # Texel k covers [k - 0.5, k + 0.5) -> marker plane (x right, y up, metres) -> supersampled image.
    M = np.array([[2 * half / N, 0, -half + half / N], [0, -2 * half / N, half - half / N], [0, 0, 1.0]])
    A = np.array([[S, 0, 0.5 * S - 0.5], [0, S, 0.5 * S - 0.5], [0, 0, 1.0]])
    H = A @ K @ np.column_stack([T_cam_marker[:3, 0], T_cam_marker[:3, 1], T_cam_marker[:3, 3]]) @ M
    img = np.full((h * S, w * S), 0.4, np.float32)
    warped = cv2.warpPerspective(tex, H, (w * S, h * S), flags=cv2.INTER_NEAREST, borderValue=-1.0)
    np.copyto(img, warped, where=warped >= 0)
    return cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)


def test_corners_match_an_independent_warp_perspective_render() -> None:
    cam = c615_like()
    marker = MarkerSpec(dictionary="DICT_4X4_50", id=11, size=0.015, T_part_marker=np.eye(4))
    slab = trimesh.creation.box(extents=(0.025, 0.025, 0.004))
    slab.apply_translation((0.0, 0.0, -0.002))
    det = MarkerDetector(["DICT_4X4_50"])
    ours, theirs = [], []
    for k in range(4):
        # Tilted 25-40 deg and rolled a little: perspective, edges off the pixel axes by 1-4 deg.
        T = geometry.from_rotvec(
            np.radians([180.0 + 25.0 + 5 * k, 8.0 - 4 * k, 1.0 + k]), np.array([0.01 * k, 0.0, 0.45])
        )
        truth = project(T, marker_corners_part(marker), cam.K, cam.dist_array)
        r = render_scene(
            [RenderObject(slab, (0.6, 0.6, 0.6), [marker], T)],
            cam.K,
            cam.width,
            cam.height,
            background=np.full((cam.height, cam.width, 3), 0.4, np.float32),
        )
        for img, out in ((r.image[..., 0], ours), (_warp_render(marker, T, cam.K, cam.width, cam.height), theirs)):
            grey = (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8)
            found = det.detect(grey)
            assert ("DICT_4X4_50", 11) in found
            out.append(found[("DICT_4X4_50", 11)] - truth)
    rms_ours = float(np.sqrt(np.mean(np.concatenate(ours) ** 2)))
    rms_theirs = float(np.sqrt(np.mean(np.concatenate(theirs) ** 2)))
    assert rms_theirs < 0.05, rms_theirs  # the check itself is exact to the detector's precision
    assert rms_ours < max(0.05, 1.5 * rms_theirs), (rms_ours, rms_theirs)
