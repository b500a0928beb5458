"""Camera calibration from ChArUco board images (OpenCV ``CharucoDetector`` + ``calibrateCamera``)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from pydantic import Field

from asmteach.core.errors import UserError
from asmteach.core.models import CameraIntrinsics, StrictModel
from asmteach.plugins.detectors.aruco.markers import get_dictionary

__all__ = ["BoardSpec", "CalibrationResult", "calibrate_charuco", "make_board"]


class BoardSpec(StrictModel):
    """A ChArUco board: squares along x and y, square and marker sides in metres, dictionary."""

    squares_x: int = Field(7, ge=3)
    squares_y: int = Field(5, ge=3)
    square: float = Field(0.04, gt=0)
    marker: float = Field(0.03, gt=0)
    dictionary: str = "DICT_5X5_100"


def make_board(spec: BoardSpec) -> cv2.aruco.CharucoBoard:
    """The OpenCV board object of ``spec``."""
    if spec.marker >= spec.square:
        raise UserError(f"board marker side {spec.marker} m must be smaller than the square side {spec.square} m")
    return cv2.aruco.CharucoBoard((spec.squares_x, spec.squares_y), spec.square, spec.marker,
                                  get_dictionary(spec.dictionary))


@dataclass
class CalibrationResult:
    """Intrinsics, RMS reprojection error (pixels) and how many images were used."""

    camera: CameraIntrinsics
    rms_px: float
    images_used: int
    images_total: int


def calibrate_charuco(images: Sequence[np.ndarray], spec: BoardSpec, *, min_corners: int = 8,
                      model: str = "k1k2p1p2k3") -> CalibrationResult:
    """Calibrate from views of a ChArUco board; :class:`UserError` when too few views show it."""
    board = make_board(spec)
    detector = cv2.aruco.CharucoDetector(board)
    obj_all, img_all = [], []
    size = None
    for i, img in enumerate(images):
        h, w = img.shape[:2]
        if size is None:
            size = (w, h)
        elif size != (w, h):
            raise UserError(f"image {i} is {w}x{h} but the first image is {size[0]}x{size[1]}; use one camera mode")
        grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 else img
        ch_corners, ch_ids, _, _ = detector.detectBoard(grey)
        if ch_ids is None or len(ch_ids) < min_corners:
            continue
        obj, imgp = board.matchImagePoints(ch_corners, ch_ids)
        if obj is None or len(obj) < min_corners:
            continue
        obj_all.append(obj.astype(np.float32))
        img_all.append(imgp.astype(np.float32))
    if len(obj_all) < 3:
        raise UserError(
            f"the board was found in only {len(obj_all)} of {len(images)} image(s); at least 3 are needed "
            f"(board {spec.squares_x}x{spec.squares_y} squares, {spec.dictionary})"
        )
    assert size is not None
    flags = 0 if model == "k1k2p1p2k3" else cv2.CALIB_FIX_K3
    rms, K, dist, _, _ = cv2.calibrateCamera(obj_all, img_all, size, None, None, flags=flags)
    cam = CameraIntrinsics(K=K, dist=np.asarray(dist).ravel().tolist(), width=size[0], height=size[1])
    return CalibrationResult(camera=cam, rms_px=float(rms), images_used=len(obj_all), images_total=len(images))
