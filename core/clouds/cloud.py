"""A point cloud as read from a file: points in metres, every other field, organisation, sensor pose."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass
class Cloud:
    """A cloud as read from a file: points in the file's frame (metres) and every other field.

    ``points`` is ``(n, 3) float64`` in metres (after any unit conversion), NaN rows kept (an organized
    cloud's invalid pixels); ``fields`` maps each extra field name to its ``(n,)`` or ``(n, count)`` array
    in the file's type (``label`` uint32, ``rgba`` uint32, ...). ``width`` x ``height`` is the PCD
    organisation (``height == 1``: unorganized). ``T_data_sensor`` is the sensor pose in the cloud's frame
    (4x4, metres) when the file gives one that says something (a PCD ``VIEWPOINT`` other than PCL's
    identity default; a PLY ``comment viewpoint``, which gives the centre only: identity rotation).
    """

    points: np.ndarray
    fields: dict[str, np.ndarray] = field(default_factory=dict)
    width: int = 0
    height: int = 1
    T_data_sensor: np.ndarray | None = None
    path: Path | None = None
    encoding: str = ""
    """``ascii``, ``binary``, ``binary_compressed`` (PCD) or ``open3d`` (PLY/XYZ)."""
    scale: float = 1.0
    """Factor applied to the file's coordinates to get metres (0.001 for a millimetre cloud)."""
    notes: list[str] = field(default_factory=list)

    @property
    def organized(self) -> bool:
        """Whether the cloud is a ``height x width`` image of points (a depth sensor's frame)."""
        return self.height > 1

    @property
    def finite(self) -> np.ndarray:
        """``(n,) bool``: rows whose three coordinates are finite (the sensor gave a return)."""
        return np.all(np.isfinite(self.points), axis=1)

    def valid_points(self) -> np.ndarray:
        """``(m, 3)`` finite points (metres, the file's frame)."""
        return self.points[self.finite]

    @property
    def viewpoint(self) -> np.ndarray | None:
        """``(3,)`` sensor centre in the cloud's frame (metres), or ``None`` when the file says nothing."""
        return None if self.T_data_sensor is None else self.T_data_sensor[:3, 3].copy()

    @property
    def labels(self) -> np.ndarray | None:
        """The ``label`` field (``(n,)`` ints), or ``None``."""
        lab = self.fields.get("label")
        return None if lab is None else np.asarray(lab).reshape(len(self.points))

    @property
    def colors(self) -> np.ndarray | None:
        """``(n, 3) uint8`` RGB from a PCD ``rgb``/``rgba`` field (packed ``0xAARRGGBB``) or a PLY's colours."""
        if "colors" in self.fields:
            return self.fields["colors"]
        for name in ("rgba", "rgb"):
            if name in self.fields:
                packed = np.ascontiguousarray(self.fields[name]).reshape(len(self.points))
                as_u32 = packed.view("<u4") if packed.dtype.itemsize == 4 else packed.astype("<u4")
                return np.stack([(as_u32 >> 16) & 255, (as_u32 >> 8) & 255, as_u32 & 255], axis=1).astype(np.uint8)
        return None

    def grid(self, values: np.ndarray | None = None) -> np.ndarray:
        """``values`` (default: the points) as the ``(height, width, ...)`` image of an organized cloud."""
        if not self.organized:
            raise ValueError("the cloud is not organized (PCD HEIGHT 1): it has no image grid")
        v = self.points if values is None else np.asarray(values)
        return v.reshape(self.height, self.width, *v.shape[1:])
