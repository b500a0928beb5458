"""The one point-cloud reader: PCD (ascii, binary, binary_compressed), PLY and XYZ, units, and frames.

:func:`read_cloud` reads the scenes ``asmteach detect`` is given (real Kinect files as well as our own
renders, :func:`asmteach.core.perception.depth_camera.write_cloud_ply`) and a part's model given as a
scan (:func:`asmteach.core.parts.build_cloud_part`).

What a file may hold, and what comes back (:class:`Cloud`):

* PCD v0.7 (PCL's format), all three encodings. ``binary_compressed`` is PCL's LZF-compressed
  structure-of-arrays layout, decompressed by :func:`lzf_decompress` (pure Python, 0.4-0.6 s for a
  640x480 Kinect frame: no C extension to build, and the one path CI tests).
  Organized clouds (``HEIGHT > 1``) keep their NaN rows, so ``points.reshape(height, width, 3)`` is the
  depth image's grid; extra fields (``label``, ``rgb``/``rgba``, normals, anything) come back in
  ``fields`` by name, one row per point. The ``VIEWPOINT tx ty tz qw qx qy qz`` header is the sensor's
  pose in the cloud's frame (``T_data_sensor``); PCL writes the identity when it knows nothing, and a
  sensor driver writes it because its points *are* in the sensor frame.
* PLY and XYZ (``.xyz``, ``.xyzn``, ``.xyzrgb``, ``.pts``) through Open3D, NaNs kept; a PLY's
  ``comment viewpoint X Y Z`` line (what our renderer writes) is the camera centre in the cloud's frame.

Units: clouds are metres inside. ``units="auto"`` looks at the extent (a depth sensor sees a few metres,
a part is at most ~1 m) and converts a cloud that is plainly in millimetres, with a warning in the log and
in ``Cloud.notes``; ``units="m"`` refuses it (:class:`UserError`); ``units="mm"`` scales by 0.001.

Frames. A sensor gives its cloud in its camera frame (OpenCV: x right, y down, z forward, metres), while
the detectors want the world frame (z up, the table top at the configured height). :func:`to_world`
maps a camera-frame cloud to the world with either the camera's pose from an extrinsics file
(:func:`load_extrinsics`) or, when none is given, the table plane found in the cloud
(:func:`table_frame`: z along the table normal toward the camera, x along the optical axis projected on
the table, origin below the camera at the table height), and says which it used. :func:`guess_frame`
tells a camera-frame cloud from a world-frame one.

The package: :mod:`.cloud` (:class:`Cloud`), :mod:`.lzf` (PCL's compression), :mod:`.pcd` (PCD read and
write), :mod:`.read` (:func:`read_cloud`: every format, PLY/XYZ through Open3D), :mod:`.units` (metres or
millimetres), :mod:`.extrinsics` (a camera pose from a file) and :mod:`.frames` (the table plane, camera
frame to world, which frame a cloud is in).
"""

from __future__ import annotations

from asmteach.core.clouds.cloud import Cloud
from asmteach.core.clouds.extrinsics import Extrinsics, load_extrinsics
from asmteach.core.clouds.frames import TableFrame, WorldCloud, depth_sigma, guess_frame, table_frame, to_world
from asmteach.core.clouds.lzf import lzf_decompress, lzf_literal
from asmteach.core.clouds.pcd import read_pcd, write_pcd
from asmteach.core.clouds.read import CLOUD_SUFFIXES, read_cloud
from asmteach.core.clouds.units import robust_extent

__all__ = [
    "CLOUD_SUFFIXES",
    "Cloud",
    "Extrinsics",
    "TableFrame",
    "WorldCloud",
    "depth_sigma",
    "guess_frame",
    "load_extrinsics",
    "lzf_decompress",
    "lzf_literal",
    "read_cloud",
    "read_pcd",
    "robust_extent",
    "table_frame",
    "to_world",
    "write_pcd",
]
