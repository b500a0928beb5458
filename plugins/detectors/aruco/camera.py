"""Camera intrinsics files: read, write and the C615-like default.

The file layout is ROS ``camera_info`` / OpenCV style::

    image_width: 1280
    image_height: 720
    camera_matrix: {rows: 3, cols: 3, data: [fx, 0, cx, 0, fy, cy, 0, 0, 1]}
    distortion_model: plumb_bob
    distortion_coefficients: {rows: 1, cols: 5, data: [k1, k2, p1, p2, k3]}

``camera_matrix`` may also be a nested 3x3 list and ``distortion_coefficients``
a flat list. Files written by OpenCV's ``cv::FileStorage`` (``%YAML:1.0``, with
``camera_matrix``/``distortion_coefficients`` or ``K``/``D`` nodes and
``image_width``/``image_height``) are read through ``cv2.FileStorage``.
Pixel coordinates follow OpenCV: the centre of the top-left pixel is (0, 0).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np

from asmteach.core.errors import UserError
from asmteach.core.io import read_yaml, write_text
from asmteach.core.models import CameraIntrinsics

__all__ = ["c615_like", "load_camera", "save_camera"]

C615_DIAGONAL_FOV_DEG = 78.0


def c615_like(
    width: int = 1280, height: int = 720, diagonal_fov_deg: float = C615_DIAGONAL_FOV_DEG
) -> CameraIntrinsics:
    """A Logicool C615-like pinhole camera: square pixels, centred principal point, no distortion."""
    f = 0.5 * float(np.hypot(width, height)) / np.tan(np.radians(0.5 * diagonal_fov_deg))
    K = np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
    return CameraIntrinsics(K=K, dist=[0.0] * 5, width=width, height=height)


def _matrix(node: Any, shape: tuple[int, int] | None, what: str, path: Path) -> np.ndarray:
    if isinstance(node, dict):
        if "data" not in node:
            raise UserError(f"{path}: {what} needs a data list (OpenCV/ROS layout: rows, cols, data)")
        arr = np.asarray(node["data"], dtype=float)
        if "rows" in node and "cols" in node:
            arr = arr.reshape(int(node["rows"]), int(node["cols"]))
    else:
        arr = np.asarray(node, dtype=float)
    if shape is not None:
        try:
            arr = arr.reshape(shape)
        except ValueError:
            raise UserError(f"{path}: {what} must have {shape[0] * shape[1]} numbers, got {arr.size}") from None
    return arr


def _from_filestorage(path: Path) -> CameraIntrinsics:
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:

        def node(*names: str) -> Any:
            for n in names:
                nd = fs.getNode(n)
                if not nd.empty():
                    return nd
            return None

        K, D = node("camera_matrix", "K"), node("distortion_coefficients", "D", "dist_coeffs")
        w, h = node("image_width", "width"), node("image_height", "height")
        if K is None or w is None or h is None:
            raise UserError(f"{path}: needs camera_matrix, image_width and image_height nodes")
        dist = [] if D is None else D.mat().ravel().tolist()
        return _build(K.mat(), dist or [0.0] * 5, int(w.real()), int(h.real()), path)
    finally:
        fs.release()


def _build(K: np.ndarray, dist: list[float], width: int, height: int, path: Path) -> CameraIntrinsics:
    K = np.asarray(K, dtype=float).reshape(3, 3)
    if K[0, 0] <= 0 or K[1, 1] <= 0 or not np.allclose(K[2], [0, 0, 1]):
        raise UserError(f"{path}: camera_matrix must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0")
    if len(dist) not in (4, 5, 8, 12, 14):
        raise UserError(f"{path}: distortion_coefficients takes 4, 5, 8, 12 or 14 numbers (OpenCV), got {len(dist)}")
    return CameraIntrinsics(K=K, dist=[float(x) for x in dist], width=int(width), height=int(height))


def load_camera(path: str | Path) -> CameraIntrinsics:
    """Read a camera intrinsics file (see the module docstring for the layouts)."""
    p = Path(path)
    if not p.is_file():
        raise UserError(f"{p}: no such camera file")
    if p.read_text(encoding="utf-8", errors="replace").lstrip().startswith("%YAML:1.0"):
        return _from_filestorage(p)
    raw = read_yaml(p)
    if not isinstance(raw, dict):
        raise UserError(f"{p}: a camera file must be a YAML mapping")
    known = {
        "image_width",
        "image_height",
        "camera_matrix",
        "distortion_model",
        "distortion_coefficients",
        "camera_name",
        "notes",
    }
    extra = sorted(set(raw) - known)
    if extra:
        raise UserError(f"{p}: unknown key(s) {extra}; a camera file takes {sorted(known)}")
    for key in ("image_width", "image_height", "camera_matrix"):
        if key not in raw:
            raise UserError(f"{p}: {key}: required key is missing")
    K = _matrix(raw["camera_matrix"], (3, 3), "camera_matrix", p)
    dist = raw.get("distortion_coefficients", [0.0] * 5)
    dist_arr = _matrix(dist, None, "distortion_coefficients", p).ravel().tolist()
    return _build(K, dist_arr, int(raw["image_width"]), int(raw["image_height"]), p)


def save_camera(path: str | Path, camera: CameraIntrinsics, *, name: str = "camera", notes: str = "") -> Path:
    """Write ``camera`` in the ROS/OpenCV layout (atomically)."""
    K = np.asarray(camera.K, dtype=float)
    lines = [
        f"camera_name: {name}",
        f"image_width: {camera.width}",
        f"image_height: {camera.height}",
        "camera_matrix: {rows: 3, cols: 3, data: [" + ", ".join(f"{x:.10g}" for x in K.ravel()) + "]}",
        "distortion_model: plumb_bob",
        f"distortion_coefficients: {{rows: 1, cols: {len(camera.dist)}, data: ["
        + ", ".join(f"{x:.10g}" for x in camera.dist)
        + "]}",
    ]
    if notes:
        lines.append(f"notes: {notes!r}")
    return write_text(path, "\n".join(lines) + "\n")
