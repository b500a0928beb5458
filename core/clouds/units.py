"""Metres or millimetres: a cloud's unit told from its extent, and the conversion."""

from __future__ import annotations

import logging

import numpy as np

from asmteach.core.clouds.cloud import Cloud
from asmteach.core.errors import UserError

log = logging.getLogger(__name__)

# A depth sensor sees a few metres at most (Kinect v1: 0.4-4 m, up to ~10 m of noise); a scene whose
# robust extent exceeds this many "metres" is in millimetres. A part is 10 mm to 1 m (core.parts), so a
# part's scan more than this wide is in millimetres too.
MAX_SCENE_EXTENT_M = 30.0
MAX_PART_EXTENT_M = 2.0


def robust_extent(points: np.ndarray) -> float:
    """Largest 1st-99th percentile spread over x, y, z of the finite points (units of the points)."""
    pts = points[np.all(np.isfinite(points), axis=1)]
    if len(pts) == 0:
        return 0.0
    sample = pts[:: max(1, len(pts) // 20000)]
    lo, hi = np.percentile(sample, [1, 99], axis=0)
    return float(np.max(hi - lo))


def apply_units(cloud: Cloud, units: str, kind: str, what: str) -> None:
    """Convert ``cloud`` to metres in place: ``units`` mm scales by 0.001; ``auto`` scales a cloud too wide
    for metres (with a note and a warning); ``m`` refuses one (:class:`UserError`). ``kind`` (scene or part)
    sets the widest extent metres may have; ``what`` names the input in messages."""
    name = cloud.path.name if cloud.path is not None else "cloud"
    if units == "mm":
        _scale(cloud, 0.001)
        return
    limit = MAX_PART_EXTENT_M if kind == "part" else MAX_SCENE_EXTENT_M
    ext = robust_extent(cloud.points)
    if ext <= limit:
        return
    if units == "m":
        raise UserError(
            f"{what}: {name} spans {ext:.0f} units, too wide for metres (a {kind} is at most {limit:.0f} m); "
            "it looks like millimetres: pass units mm"
        )
    if ext / 1000.0 > limit:
        raise UserError(f"{what}: {name} spans {ext:.0f} units, too wide for metres or millimetres; check the file")
    _scale(cloud, 0.001)
    note = f"{name} spans {ext:.0f} units: read as millimetres and scaled to metres"
    cloud.notes.append(note)
    log.warning("%s: %s", what, note)


def _scale(cloud: Cloud, s: float) -> None:
    cloud.points = cloud.points * s
    cloud.scale *= s
    if cloud.T_data_sensor is not None:
        cloud.T_data_sensor = cloud.T_data_sensor.copy()
        cloud.T_data_sensor[:3, 3] *= s
