"""Camera calibration from ChArUco or plain chessboard photos (OpenCV ``calibrateCamera``).

ChArUco boards are found with ``CharucoDetector``; chessboards with
``findChessboardCorners`` refined by ``cornerSubPix`` (the recipe of OpenCV's
``calibration.cpp`` sample). Object points are in the board frame, metres.
Each result carries the RMS reprojection error over all corners, the RMS of
each view (its corners re-projected with ``projectPoints`` through the
calibrated camera and that view's pose), the photos skipped because the board
was not found, and the detected corners of every used view (for a coverage
picture: :func:`draw_coverage`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from pydantic import Field

from asmteach.core.errors import UserError
from asmteach.core.models import CameraIntrinsics, StrictModel
from asmteach.plugins.detectors.aruco.markers import get_dictionary

__all__ = [
    "MODELS",
    "BoardSpec",
    "CalibrationResult",
    "ChessboardSpec",
    "calibrate_charuco",
    "calibrate_chessboard",
    "draw_coverage",
    "make_board",
]

MODELS = {
    "k1k2p1p2k3": ("k1 k2 p1 p2 k3", 0),
    "k1k2p1p2": ("k1 k2 p1 p2 (k3 = 0)", cv2.CALIB_FIX_K3),
}
"""Distortion models offered: name -> (description, OpenCV flags)."""


class BoardSpec(StrictModel):
    """A ChArUco board: squares along x and y, square and marker sides in metres, dictionary."""

    squares_x: int = Field(7, ge=3)
    squares_y: int = Field(5, ge=3)
    square: float = Field(0.04, gt=0)
    marker: float = Field(0.03, gt=0)
    dictionary: str = "DICT_5X5_100"


class ChessboardSpec(StrictModel):
    """A plain chessboard: inner corners along x (``cols``) and y (``rows``), square side in metres."""

    cols: int = Field(9, ge=2)
    rows: int = Field(6, ge=2)
    square: float = Field(0.025, gt=0)

    def object_points(self) -> np.ndarray:
        """``(cols * rows, 3) float32`` inner corners in the board frame (z = 0), metres, in OpenCV's order."""
        grid = np.mgrid[0 : self.cols, 0 : self.rows].T.reshape(-1, 2) * self.square
        return np.column_stack([grid, np.zeros(len(grid))]).astype(np.float32)


def make_board(spec: BoardSpec) -> cv2.aruco.CharucoBoard:
    """The OpenCV board object of ``spec``."""
    if spec.marker >= spec.square:
        raise UserError(f"board marker side {spec.marker} m must be smaller than the square side {spec.square} m")
    return cv2.aruco.CharucoBoard(
        (spec.squares_x, spec.squares_y), spec.square, spec.marker, get_dictionary(spec.dictionary)
    )


@dataclass
class CalibrationResult:
    """Intrinsics, reprojection errors (pixels), and which photos were used or skipped."""

    camera: CameraIntrinsics
    rms_px: float
    """RMS reprojection error over every corner of every used view (``calibrateCamera``'s value)."""
    images_used: int
    images_total: int
    per_view_px: list[float] = field(default_factory=list)
    """RMS reprojection error of each used view, pixels (same order as ``used``)."""
    used: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    """Names of the photos whose board was not found."""
    corners: list[np.ndarray] = field(default_factory=list)
    """``(n_i, 2)`` detected corners of each used view, pixels."""
    model: str = ""
    """Camera model in words, e.g. ``"pinhole fx = fy (CALIB_FIX_ASPECT_RATIO), distortion k1 k2 p1 p2 k3"``."""


def _names(n: int, names: Sequence[str] | None) -> list[str]:
    if names is None:
        return [f"image {i}" for i in range(n)]
    if len(names) != n:
        raise ValueError(f"{len(names)} names for {n} images")
    return list(names)


def _grey(img: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 else img


def _image_size(images: Sequence[np.ndarray], names: list[str]) -> tuple[int, int]:
    if not images:
        raise UserError("no images to calibrate from; give a folder of board photos")
    h, w = images[0].shape[:2]
    for name, img in zip(names, images, strict=True):
        if img.shape[:2] != (h, w):
            hh, ww = img.shape[:2]
            raise UserError(f"{name} is {ww}x{hh} but the first image is {w}x{h}; use photos of one camera mode")
    return w, h


def _calibrate(
    obj_all: list[np.ndarray],
    img_all: list[np.ndarray],
    size: tuple[int, int],
    used: list[str],
    skipped: list[str],
    total: int,
    board: str,
    *,
    model: str,
    fix_aspect: bool,
) -> CalibrationResult:
    """``calibrateCamera`` on the views found, then each view's RMS through ``projectPoints``."""
    if model not in MODELS:
        raise UserError(f"unknown distortion model {model!r}; use one of {sorted(MODELS)}")
    if len(obj_all) < 3:
        raise UserError(
            f"the board was found in only {len(obj_all)} of {total} image(s); at least 3 are needed ({board}); "
            "check the board size options (inner corners for a chessboard, squares for ChArUco)"
        )
    words, flags = MODELS[model]
    # CALIB_FIX_ASPECT_RATIO keeps the fx/fy of the initial matrix: start from fx = fy (square pixels).
    K0 = np.eye(3)
    if fix_aspect:
        flags |= cv2.CALIB_FIX_ASPECT_RATIO
    rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(obj_all, img_all, size, K0, None, flags=flags)
    dist = np.asarray(dist).ravel()
    per_view = []
    for obj, img, r, t in zip(obj_all, img_all, rvecs, tvecs, strict=True):
        proj, _ = cv2.projectPoints(obj, r, t, K, dist)
        per_view.append(float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img.reshape(-1, 2)) ** 2, axis=1)))))
    cam = CameraIntrinsics(K=K, dist=dist.tolist(), width=size[0], height=size[1])
    aspect = "fx = fy (CALIB_FIX_ASPECT_RATIO)" if fix_aspect else "fx, fy free"
    return CalibrationResult(
        camera=cam,
        rms_px=float(rms),
        images_used=len(obj_all),
        images_total=total,
        per_view_px=per_view,
        used=used,
        skipped=skipped,
        corners=[np.asarray(i, dtype=np.float64).reshape(-1, 2) for i in img_all],
        model=f"pinhole {aspect}, distortion {words} (plumb_bob)",
    )


def calibrate_charuco(
    images: Sequence[np.ndarray],
    spec: BoardSpec,
    *,
    names: Sequence[str] | None = None,
    min_corners: int = 8,
    model: str = "k1k2p1p2k3",
    fix_aspect: bool = False,
) -> CalibrationResult:
    """Calibrate from views of a ChArUco board; :class:`UserError` when fewer than 3 views show it."""
    board = make_board(spec)
    detector = cv2.aruco.CharucoDetector(board)
    labels = _names(len(images), names)
    size = _image_size(images, labels)
    obj_all, img_all, used, skipped = [], [], [], []
    for name, img in zip(labels, images, strict=True):
        ch_corners, ch_ids, _, _ = detector.detectBoard(_grey(img))
        obj = imgp = None
        if ch_ids is not None and len(ch_ids) >= min_corners:
            obj, imgp = board.matchImagePoints(ch_corners, ch_ids)
        if obj is None or len(obj) < min_corners:
            skipped.append(name)
            continue
        obj_all.append(obj.astype(np.float32))
        img_all.append(imgp.astype(np.float32))
        used.append(name)
    what = f"ChArUco {spec.squares_x}x{spec.squares_y} squares, {spec.dictionary}"
    return _calibrate(obj_all, img_all, size, used, skipped, len(images), what, model=model, fix_aspect=fix_aspect)


def calibrate_chessboard(
    images: Sequence[np.ndarray],
    spec: ChessboardSpec,
    *,
    names: Sequence[str] | None = None,
    model: str = "k1k2p1p2k3",
    fix_aspect: bool = False,
) -> CalibrationResult:
    """Calibrate from views of a plain chessboard (``findChessboardCorners`` + ``cornerSubPix``).

    A view counts only when all ``cols x rows`` inner corners are found (a
    chessboard has no ids: a partial view cannot be matched to the board).
    """
    labels = _names(len(images), names)
    size = _image_size(images, labels)
    pattern = (spec.cols, spec.rows)
    obj = spec.object_points()
    find_flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
    # OpenCV's calibration sample: 11x11 search window, 30 iterations or 1e-4 px.
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 1e-4)
    obj_all, img_all, used, skipped = [], [], [], []
    for name, img in zip(labels, images, strict=True):
        grey = _grey(img)
        ok, corners = cv2.findChessboardCorners(grey, pattern, flags=find_flags)
        if not ok:
            skipped.append(name)
            continue
        corners = cv2.cornerSubPix(grey, corners, (11, 11), (-1, -1), criteria)
        obj_all.append(obj)
        img_all.append(corners.astype(np.float32))
        used.append(name)
    what = f"chessboard {spec.cols}x{spec.rows} inner corners"
    return _calibrate(obj_all, img_all, size, used, skipped, len(images), what, model=model, fix_aspect=fix_aspect)


def draw_coverage(result: CalibrationResult, *, cells: tuple[int, int] = (8, 6)) -> tuple[np.ndarray, float]:
    """Picture of every used view's corners on one canvas of the image size, and the covered fraction.

    Each view gets its own colour, its corners as dots and their convex hull
    as an outline. The fraction is of a ``cells`` grid over the image holding
    at least one corner: corners only in the middle leave the distortion at
    the edges unconstrained.
    """
    w, h = result.camera.width, result.camera.height
    canvas = np.full((h, w, 3), 40, np.uint8)
    grid = np.zeros((cells[1], cells[0]), bool)
    for k, pts in enumerate(result.corners):
        hue = int(180 * k / max(1, len(result.corners)))
        colour = cv2.cvtColor(np.uint8([[[hue, 220, 255]]]), cv2.COLOR_HSV2BGR)[0, 0].tolist()
        hull = cv2.convexHull(pts.astype(np.float32)).astype(np.int32)
        cv2.polylines(canvas, [hull], True, colour, 1, cv2.LINE_AA)
        for x, y in pts:
            cv2.circle(canvas, (round(x), round(y)), 2, colour, -1, cv2.LINE_AA)
        ix = np.clip((pts[:, 0] / w * cells[0]).astype(int), 0, cells[0] - 1)
        iy = np.clip((pts[:, 1] / h * cells[1]).astype(int), 0, cells[1] - 1)
        grid[iy, ix] = True
    for i in range(1, cells[0]):
        cv2.line(canvas, (i * w // cells[0], 0), (i * w // cells[0], h - 1), (90, 90, 90), 1)
    for j in range(1, cells[1]):
        cv2.line(canvas, (0, j * h // cells[1]), (w - 1, j * h // cells[1]), (90, 90, 90), 1)
    frac = float(grid.mean())
    cv2.putText(
        canvas,
        f"{len(result.corners)} views, {frac:.0%} of cells covered",
        (8, 20),
        cv2.FONT_HERSHEY_SIMPLEX,
        0.5,
        (255, 255, 255),
        1,
        cv2.LINE_AA,
    )
    return canvas, frac
