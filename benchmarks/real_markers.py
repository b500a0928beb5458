"""Benchmark on real photos: chessboard calibration vs OpenCV's reference, and marker groups of a real ChArUco
photo vs a plain solvePnP baseline.

Run: .venv/bin/python benchmarks/real_markers.py [--data ../shared/data]
Reads the files in place (never copies them). Prints

1. our chessboard calibration of ``real/chessboard/`` (fixed aspect ratio, as
   OpenCV's reference was made, and free aspect) beside
   ``reference_left_intrinsics.yml``;
2. on ``real/aruco/choriginal.jpg`` (ChArUco 5x7 squares, 40 mm squares,
   20 mm markers, DICT_6X6_250) split four ways into two marker groups "A" and
   "B": the error of ``T_A_B`` against the printed layout for the teacher's
   per-frame estimate (:func:`teacher_split` with default settings, whose
   edge fit's line-RMS limit follows each marker's measured edge-point noise;
   with the real-photo edge limits; with OpenCV sub-pixel corners) and for plain per-group
   ``cv2.solvePnP`` on OpenCV's corners;
3. the ids found on the three ArUco photos.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from asmteach.core import geometry
from asmteach.plugins.detectors.aruco.boards import (
    charuco_marker_poses,
    solvepnp_split,
    split_board_task,
    teacher_split,
)
from asmteach.plugins.detectors.aruco.calibrate import ChessboardSpec, calibrate_chessboard
from asmteach.plugins.detectors.aruco.camera import load_camera
from asmteach.plugins.detectors.aruco.detect import MarkerDetector
from asmteach.plugins.detectors.aruco.frames import load_named_frames
from asmteach.plugins.detectors.aruco.teacher_settings import ArucoTeacherSettings

ROOT = Path(__file__).resolve().parents[1]
SQUARE, MARKER, DICT = 0.04, 0.02, "DICT_6X6_250"
# Group A = the markers whose centre (board frame, metres) passes the test; B = the rest.
SPLITS = {
    "left 2 columns / right 3": lambda t: t[0] < 0.08,
    "left 3 columns / right 2": lambda t: t[0] < 0.12,
    "top 3 rows / bottom 4": lambda t: t[1] < 0.12,
    "top 4 rows / bottom 3": lambda t: t[1] < 0.16,
}
REAL_PHOTO = ArucoTeacherSettings(edge_max_line_rms=0.35, edge_min_inliers=0.6)


def split_tasks() -> list[tuple[str, object, np.ndarray]]:
    """``(split name, task, true T_A_B)``: B's frame sits at its markers' centroid, turned 90 deg about z."""
    poses = charuco_marker_poses((5, 7), SQUARE, MARKER, DICT)
    out = []
    for name, in_a in SPLITS.items():
        ids_a = [i for i, T in poses.items() if in_a(T[:3, 3])]
        ids_b = [i for i in poses if i not in ids_a]
        centre = np.mean([poses[i][:3, 3] for i in ids_b], axis=0)
        T_A_B = geometry.from_rotation(Rotation.from_euler("z", 90, degrees=True).as_matrix(), centre)
        out.append((name, split_board_task(poses, ids_a, ids_b, T_A_B, MARKER, DICT), T_A_B))
    return out


def calibration_table(data: Path) -> list[str]:
    ref = cv2.FileStorage(str(data / "real/chessboard/reference_left_intrinsics.yml"), cv2.FILE_STORAGE_READ)
    K_ref, d_ref = ref.getNode("camera_matrix").mat(), ref.getNode("distortion_coefficients").mat().ravel()
    rms_ref = ref.getNode("avg_reprojection_error").real()
    views_ref = ref.getNode("per_view_reprojection_errors").mat().ravel()
    named = load_named_frames(data / "real/chessboard")
    names, images = [n for n, _ in named], [i for _, i in named]
    rows = ["| | fx | fy | cx | cy | k1 | k2 | p1 | p2 | k3 | RMS px | views |", "|---" * 12 + "|"]
    rows.append(
        f"| OpenCV reference (flags 2) | {K_ref[0, 0]:.2f} | {K_ref[1, 1]:.2f} | {K_ref[0, 2]:.2f} | "
        f"{K_ref[1, 2]:.2f} | " + " | ".join(f"{x:.4f}" for x in d_ref) + f" | {rms_ref:.3f} | 13 |"
    )
    per_view = []
    for fix in (True, False):
        res = calibrate_chessboard(images, ChessboardSpec(cols=9, rows=6, square=0.025), names=names, fix_aspect=fix)
        K = res.camera.K
        label = "ours, --fix-aspect" if fix else "ours, fx fy free"
        rows.append(
            f"| {label} | {K[0, 0]:.2f} | {K[1, 1]:.2f} | {K[0, 2]:.2f} | {K[1, 2]:.2f} | "
            + " | ".join(f"{x:.4f}" for x in res.camera.dist)
            + f" | {res.rms_px:.3f} | {res.images_used} |"
        )
        if fix:
            rel = (K[0, 0] / K_ref[0, 0] - 1) * 100
            rows.append(
                f"| difference | {rel:+.3f} % | | {K[0, 2] - K_ref[0, 2]:+.2f} px | "
                f"{K[1, 2] - K_ref[1, 2]:+.2f} px | | | | | | {res.rms_px - rms_ref:+.3f} | |"
            )
            per_view = list(zip(res.used, res.per_view_px, views_ref, strict=True))
    rows += ["", "| view | ours px | OpenCV px |", "|---|---|---|"]
    rows += [f"| {n} | {a:.3f} | {b:.3f} |" for n, a, b in per_view]
    return rows


def marker_table(data: Path) -> list[str]:
    cam = load_camera(data / "real/aruco/tutorial_camera_charuco.yml")
    img = cv2.imread(str(data / "real/aruco/choriginal.jpg"))
    methods = {
        "teacher, default settings (noise-adaptive line-RMS limit)": lambda t: teacher_split(img, cam, t),
        "teacher, real-photo edge limits (0.35 px, 0.6)": lambda t: teacher_split(img, cam, t, REAL_PHOTO),
        "teacher, OpenCV sub-pixel corners": lambda t: teacher_split(
            img, cam, t, ArucoTeacherSettings(corner_refinement="subpix")
        ),
        "baseline: OpenCV corners + solvePnP per group": lambda t: solvepnp_split(img, cam, t),
        "baseline: OpenCV sub-pixel corners + solvePnP": lambda t: solvepnp_split(
            img, cam, t, refine=cv2.aruco.CORNER_REFINE_SUBPIX
        ),
    }
    rows = ["| method | " + " | ".join(SPLITS) + " | mean |", "|---" * (len(SPLITS) + 2) + "|"]
    tasks = split_tasks()
    for label, fn in methods.items():
        cells, errs = [], []
        for _name, task, T_true in tasks:
            est = fn(task)
            err = est.errors(T_true)
            e_t, e_r = err.position_mm, err.angle_deg
            errs.append((e_t, e_r))
            cells.append(
                f"{e_t:.2f} mm {e_r:.2f} deg ({len(est.markers_a)}+{len(est.markers_b)} markers, {est.rms_px:.2f} px)"
            )
        m = np.mean(errs, axis=0)
        rows.append(f"| {label} | " + " | ".join(cells) + f" | {m[0]:.2f} mm {m[1]:.2f} deg |")
    return rows


def ids_table(data: Path) -> list[str]:
    rows = [
        "| photo | dictionary | ids found (teacher's detector, default / real-photo edge limits) |",
        "|---|---|---|",
    ]
    for photo, dictionary in (
        ("choriginal.jpg", DICT),
        ("singlemarkersoriginal.jpg", DICT),
        ("screen_charuco.jpg", "DICT_4X4_50"),
    ):
        img = cv2.imread(str(data / "real/aruco" / photo))
        found = []
        for lim in ((0.25, 0.85), (0.35, 0.6)):
            det = MarkerDetector([dictionary], edge_max_line_rms=lim[0], edge_min_inliers=lim[1])
            found.append(sorted(k[1] for k in det.detect(img)))
        rows.append(f"| {photo} | {dictionary} | {found[0]} / {found[1]} |")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=ROOT / ".." / "shared" / "data", help="the shared data folder")
    args = ap.parse_args()
    for title, rows in (
        ("Chessboard calibration", calibration_table(args.data)),
        ("T_A_B error of marker groups on choriginal.jpg", marker_table(args.data)),
        ("Ids", ids_table(args.data)),
    ):
        print(f"## {title}\n")
        print("\n".join(rows) + "\n")


if __name__ == "__main__":
    main()
