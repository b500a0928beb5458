"""Marker poses and ids on real photos (OpenCV's tutorial photos of printed ArUco and ChArUco boards).

``choriginal.jpg`` shows a ChArUco board of 5x7 squares (DICT_6X6_250) printed
on A4: its 17 markers split into two groups give two "parts" whose true
``T_A_B`` is the printed layout. Scale: 40 mm squares and 20 mm markers, the
values of OpenCV's ChArUco tutorial that took the photo (5 x 40 mm = 200 mm
fills the width of the A4 sheet seen; the marker/square ratio 0.5 is what the
photo's corners fit best, see docs/results/real_sensor_data.md).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from asmteach.core import geometry
from asmteach.core.pose_error import PoseError
from asmteach.plugins.detectors.aruco.boards import (
    charuco_marker_poses,
    solvepnp_split,
    split_board_task,
    teacher_split,
)
from asmteach.plugins.detectors.aruco.camera import load_camera
from asmteach.plugins.detectors.aruco.detect import MarkerDetector
from asmteach.plugins.detectors.aruco.markers import get_dictionary
from asmteach.plugins.detectors.aruco.teacher_settings import ArucoTeacherSettings

REAL_PHOTO = ArucoTeacherSettings(edge_max_line_rms=0.35, edge_min_inliers=0.6)
SPLITS = {"left/right": (0, 0.08), "left/right 3+2": (0, 0.12), "top/bottom": (1, 0.12), "top/bottom 4+3": (1, 0.16)}


@pytest.fixture(scope="module")
def charuco_photo(real_data: Path):
    cam = load_camera(real_data / "real/aruco/tutorial_camera_charuco.yml")
    img = cv2.imread(str(real_data / "real/aruco/choriginal.jpg"))
    poses = charuco_marker_poses((5, 7), 0.04, 0.02, "DICT_6X6_250")
    tasks = {}
    for name, (axis, limit) in SPLITS.items():
        ids_a = [i for i, T in poses.items() if T[axis, 3] < limit]
        ids_b = [i for i in poses if i not in ids_a]
        centre = np.mean([poses[i][:3, 3] for i in ids_b], axis=0)
        T_A_B = geometry.from_rotation(Rotation.from_euler("z", 90, degrees=True).as_matrix(), centre)
        tasks[name] = (split_board_task(poses, ids_a, ids_b, T_A_B, 0.02, "DICT_6X6_250"), T_A_B)
    return img, cam, tasks


def _mm_deg(err: PoseError) -> tuple[float, float]:
    return err.position_mm, err.angle_deg


def test_marker_groups_match_the_printed_layout_at_least_as_well_as_solvepnp(charuco_photo) -> None:
    img, cam, tasks = charuco_photo
    ours, base = [], []
    for name, (task, T_true) in tasks.items():
        est = teacher_split(img, cam, task, REAL_PHOTO)
        err = est.errors(T_true)
        e_t, e_r = err.position_mm, err.angle_deg
        # Single photo, 0.4 m away: what limits it is each group's depth (about 1 mm from 0.3 px corner noise).
        assert e_t < 1.0 and e_r < 1.0, (name, e_t, e_r)
        assert len(est.markers_a) >= 4 and len(est.markers_b) >= 5 and est.rms_px < 0.4, name
        ours.append((e_t, e_r))
        base.append(_mm_deg(solvepnp_split(img, cam, task).errors(T_true)))
    ours_m, base_m = np.mean(ours, axis=0), np.mean(base, axis=0)
    assert 0.6 < base_m[0] < 2.0 and base_m[1] < 1.5  # the baseline the issue quotes: 0.6-1.3 mm, 0.7 deg
    assert ours_m[0] <= base_m[0] and ours_m[1] <= base_m[1], (ours_m, base_m)


def test_default_settings_match_the_printed_layout_better_than_solvepnp(charuco_photo) -> None:
    # With default settings the edge fit's line-RMS limit follows the edge-point noise measured on each marker
    # (this JPEG: 0.15-0.33 px on clean edges). A fixed 0.25 px kept 6 of 17 markers here and left a group with
    # one marker, 10 mm off: 5.64 mm, 1.40 deg mean against solvePnP's 1.33 mm, 0.87 deg.
    img, cam, tasks = charuco_photo
    ours, base = [], []
    for name, (task, T_true) in tasks.items():
        est = teacher_split(img, cam, task)
        assert len(est.markers_a) >= 3 and len(est.markers_b) >= 4 and est.rms_px < 0.4, name
        ours.append(_mm_deg(est.errors(T_true)))
        base.append(_mm_deg(solvepnp_split(img, cam, task).errors(T_true)))
    ours_m, base_m = np.mean(ours, axis=0), np.mean(base, axis=0)
    assert ours_m[0] <= base_m[0] and ours_m[1] <= base_m[1], (ours_m, base_m)


def _printed_id(grey: np.ndarray, corners: np.ndarray, dictionary: str) -> int | None:
    """Read a marker's cells from the photo (cell means of the rectified square, Otsu threshold) and return the
    dictionary entry nearest in any rotation, if it is within 2 bits and no other entry is as near."""
    d = get_dictionary(dictionary)
    cells = d.markerSize + 2
    side = 12 * cells
    H = cv2.getPerspectiveTransform(
        corners.astype(np.float32), np.float32([[0, 0], [side, 0], [side, side], [0, side]])
    )
    warp = cv2.warpPerspective(grey, H, (side, side))
    # Mean of the middle half of each cell: blur and the exact corner positions matter little there.
    means = warp.reshape(cells, 12, cells, 12)[:, 3:9, :, 3:9].mean(axis=(1, 3)).astype(np.uint8)
    _, black = cv2.threshold(means, 0, 1, cv2.THRESH_BINARY_INV + cv2.THRESH_OTSU)
    bits = black.astype(bool)
    dist = []
    for mid in range(d.bytesList.shape[0]):
        ref = cv2.aruco.generateImageMarker(d, mid, cells, borderBits=1) < 128
        dist.append(min(int(np.sum(np.rot90(bits, k) != ref)) for k in range(4)))
    order = np.argsort(dist)
    best = int(order[0])
    return best if dist[best] <= 2 and dist[int(order[1])] > dist[best] else None


@pytest.mark.parametrize(
    "photo, dictionary, expected",
    [
        ("singlemarkersoriginal.jpg", "DICT_6X6_250", {23, 40, 62, 98, 124, 203}),
        ("choriginal.jpg", "DICT_6X6_250", set(range(17))),
        ("screen_charuco.jpg", "DICT_4X4_50", None),
    ],
)
def test_ids_on_real_photos_are_the_printed_ones(
    real_data: Path, photo: str, dictionary: str, expected: set[int] | None
) -> None:
    img = cv2.imread(str(real_data / "real/aruco" / photo))
    grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    found = MarkerDetector([dictionary], refine="none").detect(img)
    ids = {k[1] for k in found}
    if expected is not None:
        assert ids == expected
    # Each id is what is printed: the cells read straight from the photo give the same dictionary entry.
    for (_, mid), corners in found.items():
        assert _printed_id(grey, corners, dictionary) == mid
    # Edge-fitted corners (the real-photo limits; the defaults, whose line-RMS limit follows the measured edge
    # noise) keep only ids the coarse detection found, and their corners stay on the coarse ones.
    edges = MarkerDetector([dictionary], edge_max_line_rms=0.35, edge_min_inliers=0.6).detect(img)
    assert {k[1] for k in edges} <= ids and len(edges) >= 0.5 * len(ids)
    default = MarkerDetector([dictionary]).detect(img)
    assert {k[1] for k in default} <= ids and len(default) >= 0.3 * len(ids)
    assert all(np.abs(c - found[k]).max() < 2.0 for k, c in default.items())


def test_screen_charuco_ids_sit_where_the_board_layout_puts_them(real_data: Path) -> None:
    # The board on the screen is 6x8 squares (24 markers, ids 0-23) in OpenCV's legacy layout, held sideways.
    img = cv2.imread(str(real_data / "real/aruco/screen_charuco.jpg"))
    found = MarkerDetector(["DICT_4X4_50"], refine="subpix").detect(img)
    assert len(found) >= 15 and all(k[1] < 24 for k in found)
    poses = charuco_marker_poses((6, 8), 0.04, 0.02, "DICT_4X4_50", legacy=True)
    centres = np.array([poses[k[1]][:2, 3] for k in found])
    pix = np.array([c.mean(axis=0) for c in found.values()])
    H, _ = cv2.findHomography(centres, pix, 0)
    err = np.linalg.norm(cv2.perspectiveTransform(centres[None], H)[0] - pix, axis=1)
    assert err.max() < 4.0  # a marker with a wrong id would sit a square (~20 px) away
