"""The camera's pose in the world from an extrinsics file (``T_world_cam``, ``T_cam_world``, rvec/tvec,
translation + rotation; YAML, JSON or OpenCV FileStorage)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from asmteach.core import geometry
from asmteach.core.errors import UserError


@dataclass
class Extrinsics:
    """The camera's pose in the world, ``T_world_cam`` (4x4, metres; camera frame OpenCV's), and its source."""

    T_world_cam: np.ndarray
    source: str


def _matrix(node: Any, shape: tuple[int, ...], key: str, p: Path) -> np.ndarray:
    if isinstance(node, dict) and "data" in node:  # ROS / OpenCV-YAML style {rows, cols, data}
        node = node["data"]
    try:
        arr = np.asarray(node, dtype=float)
        arr = arr.reshape(shape)
    except (TypeError, ValueError):
        raise UserError(f"{p}: {key}: expected {'x'.join(map(str, shape))} numbers") from None
    if not np.all(np.isfinite(arr)):
        raise UserError(f"{p}: {key}: holds a non-finite number")
    return arr


def _rigid(T: np.ndarray, key: str, p: Path) -> np.ndarray:
    R = T[:3, :3]
    if not np.allclose(T[3], [0, 0, 0, 1], atol=1e-9):
        raise UserError(f"{p}: {key}: the last row must be 0 0 0 1")
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0.999:
        raise UserError(f"{p}: {key}: the rotation part is not a rotation (R R^T != I or det != 1)")
    # Re-orthonormalise: files carry 6-10 digits.
    U, _, Vt = np.linalg.svd(R)
    out = T.copy()
    out[:3, :3] = U @ Vt
    return out


EXTRINSICS_KEYS = ("T_world_cam", "T_cam_world", "rvec/tvec", "translation + rotation")


def load_extrinsics(path: str | Path) -> Extrinsics:
    """The camera's pose in the world from a YAML/JSON file (metres, radians; world z up).

    One of (the forms calibrations and hand-eye tools write):

    * ``T_world_cam``: 4x4 (nested lists or ``{rows: 4, cols: 4, data: [...]}``), the camera in the world;
    * ``T_cam_world``: 4x4, the world in the camera (its inverse);
    * ``rvec`` and ``tvec`` (3 numbers each): OpenCV's pose of a board lying on the table in the camera,
      what ``solvePnP`` or ``calibrateCamera`` give for the view (``T_cam_board``); the world is the board
      with z up (OpenCV's board z points into the board, so it is turned half a turn about x when the
      camera would otherwise be below the table);
    * ``translation`` (x y z) and ``rotation`` (quaternion ``x y z w``): the camera in the world, as a ROS
      ``TransformStamped`` or easy_handeye writes it.

    Matrices may be written as ``asmteach calibrate`` writes ``camera_matrix`` (``{rows, cols, data}``), so a
    camera YAML with a ``T_world_cam`` key added is an extrinsics file too (other keys are ignored). An
    OpenCV FileStorage file (``%YAML:1.0``) with these keys works too. :class:`UserError` names a bad file.
    """
    p = Path(path)
    if not p.is_file():
        raise UserError(f"--extrinsics: no such file {p}")
    text = p.read_text(encoding="utf-8", errors="replace")
    if text.lstrip().startswith("%YAML"):
        raw = _filestorage(p)
    else:
        from asmteach.core.io import read_yaml

        raw = read_yaml(p)
    if isinstance(raw, dict) and isinstance(raw.get("transform"), dict):
        raw = raw["transform"]  # a TransformStamped's transform
    if not isinstance(raw, dict):
        raise UserError(f"{p}: an extrinsics file must be a mapping with one of {', '.join(EXTRINSICS_KEYS)}")
    if "T_world_cam" in raw:
        T = _rigid(_matrix(raw["T_world_cam"], (4, 4), "T_world_cam", p), "T_world_cam", p)
        return Extrinsics(T, f"{p.name}: T_world_cam")
    if "T_cam_world" in raw:
        T = _rigid(_matrix(raw["T_cam_world"], (4, 4), "T_cam_world", p), "T_cam_world", p)
        return Extrinsics(geometry.invert(T), f"{p.name}: T_cam_world (inverted)")
    if "rvec" in raw and "tvec" in raw:
        rv = _matrix(raw["rvec"], (3,), "rvec", p)
        tv = _matrix(raw["tvec"], (3,), "tvec", p)
        T_board_cam = geometry.invert(geometry.from_rotvec(rv, tv))
        if T_board_cam[2, 3] >= 0:
            return Extrinsics(T_board_cam, f"{p.name}: rvec/tvec (board on the table, z up)")
        # OpenCV's board frame has z = x cross y pointing *into* the board, away from a camera that sees it:
        # for a board lying on the table that is down. Half a turn about the board's x makes the world z up.
        T_world_cam = geometry.from_rotation(np.diag([1.0, -1.0, -1.0])) @ T_board_cam
        return Extrinsics(T_world_cam, f"{p.name}: rvec/tvec (board on the table, its z turned up)")
    if "translation" in raw and "rotation" in raw:
        t, q = raw["translation"], raw["rotation"]
        if isinstance(t, dict):
            t = [t.get(k) for k in "xyz"]
        if isinstance(q, dict):
            q = [q.get(k) for k in "xyzw"]
        tv = _matrix(t, (3,), "translation", p)
        qv = _matrix(q, (4,), "rotation", p)
        if abs(np.linalg.norm(qv) - 1.0) > 1e-3:
            raise UserError(f"{p}: rotation: {qv.tolist()} is not a unit quaternion (x y z w)")
        return Extrinsics(geometry.from_quat(qv / np.linalg.norm(qv), tv), f"{p.name}: translation + rotation")
    raise UserError(f"{p}: no camera pose found; give one of {', '.join(EXTRINSICS_KEYS)}")


def _filestorage(p: Path) -> dict[str, Any]:
    import cv2

    fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
    try:
        out: dict[str, Any] = {}
        for key in ("T_world_cam", "T_cam_world", "rvec", "tvec"):
            node = fs.getNode(key)
            if not node.empty():
                mat = node.mat()
                out[key] = mat.tolist() if mat is not None else None
        return out
    finally:
        fs.release()
