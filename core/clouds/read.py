"""The one point-cloud reader: a file of any format asmteach takes (PCD, PLY, XYZ) into metres."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np

from asmteach.core import geometry
from asmteach.core.clouds.cloud import Cloud
from asmteach.core.clouds.pcd import read_pcd
from asmteach.core.clouds.units import apply_units
from asmteach.core.errors import UserError

CLOUD_SUFFIXES = frozenset({".pcd", ".ply", ".xyz", ".xyzn", ".xyzrgb", ".pts"})
"""File suffixes :func:`read_cloud` reads."""

PLY_VIEWPOINT = "comment viewpoint"
"""PLY header line prefix followed by the camera centre ``X Y Z`` (the cloud's frame, metres)."""


def read_cloud(
    path: str | Path,
    *,
    units: Literal["auto", "m", "mm"] = "auto",
    kind: Literal["scene", "part"] = "scene",
    what: str = "cloud",
) -> Cloud:
    """Read any cloud asmteach takes (PCD, PLY, XYZ) into metres; see :mod:`asmteach.core.clouds`.

    ``kind`` sets the unit check: a ``scene`` (a sensor's view, up to tens of metres) or a ``part``'s scan
    (at most 2 m across, as a part's mesh). ``what`` names the input in messages (``--cloud``).
    :class:`UserError` for a missing, unreadable or empty file, or millimetres given as ``units="m"``.
    """
    p = Path(path)
    if not p.is_file():
        raise UserError(f"{what}: no such file {p}")
    suffix = p.suffix.lower()
    if suffix not in CLOUD_SUFFIXES:
        raise UserError(f"{what}: {p.name} is not a point-cloud file; give a .pcd, .ply or .xyz")
    cloud = read_pcd(p) if suffix == ".pcd" else _read_open3d(p)
    fin = cloud.finite
    if not fin.any():
        raise UserError(f"{what}: {p.name} holds no finite point ({len(cloud.points)} rows, all NaN or empty)")
    apply_units(cloud, units, kind, what)
    return cloud


def _read_open3d(p: Path) -> Cloud:
    import asmteach.core  # noqa: F401  (loads libusb before open3d)

    import open3d as o3d  # isort: skip

    pc = o3d.io.read_point_cloud(str(p), remove_nan_points=False, remove_infinite_points=False)
    pts = np.asarray(pc.points, dtype=np.float64).reshape(-1, 3)
    fields: dict[str, np.ndarray] = {}
    if pc.has_colors():
        fields["colors"] = np.clip(np.round(np.asarray(pc.colors) * 255.0), 0, 255).astype(np.uint8)
    if pc.has_normals():
        fields["normals"] = np.asarray(pc.normals, dtype=np.float64)
    T = None
    if p.suffix.lower() == ".ply":
        eye = _ply_viewpoint(p)
        if eye is not None:
            T = geometry.from_rotation(np.eye(3), eye)
    if len(pts) == 0 and p.stat().st_size > 0:
        raise UserError(f"{p}: no points read: the file holds none, or is not a point-cloud {p.suffix} Open3D reads")
    return Cloud(points=pts, fields=fields, width=len(pts), height=1, T_data_sensor=T, path=p, encoding="open3d")


def _ply_viewpoint(p: Path) -> np.ndarray | None:
    with p.open("rb") as fh:
        head = fh.read(65536)
    for raw in head.split(b"\n"):
        line = raw.decode("ascii", errors="replace").strip()
        if line == "end_header":
            return None
        if line.startswith(PLY_VIEWPOINT + " "):
            try:
                eye = np.array([float(v) for v in line[len(PLY_VIEWPOINT) :].split()[:3]], dtype=float)
            except ValueError:
                eye = np.array([])
            if eye.shape != (3,) or not np.all(np.isfinite(eye)):
                raise UserError(f"{p}: header line {line!r} should hold 3 finite numbers; fix it or give --viewpoint")
            return eye
    return None
