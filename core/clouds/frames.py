"""Frames of a cloud: the table plane and the world frame it defines, a camera-frame cloud mapped to the
world, and which of the two frames a cloud is in."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from asmteach.core import geometry
from asmteach.core.clouds.cloud import Cloud
from asmteach.core.clouds.extrinsics import Extrinsics
from asmteach.core.errors import UserError


@dataclass
class TableFrame:
    """The world frame a table plane defines, seen from the camera.

    ``T_world_cam`` (4x4): world z along the table normal toward the camera, x the optical axis projected on
    the table, origin below the camera at ``table_height``. ``normal_cam`` and ``offset_cam`` are the plane
    in the camera frame (``normal . p = offset``, metres, normal toward the camera); ``inliers`` the share
    of the valid points on it; ``camera_height`` the camera centre's height above the table, metres;
    ``tilt_deg`` the angle between the optical axis and the table.
    """

    T_world_cam: np.ndarray
    normal_cam: np.ndarray
    offset_cam: float
    inliers: float
    camera_height: float
    tilt_deg: float
    table_height: float


def depth_sigma(z: np.ndarray) -> np.ndarray:
    """Kinect v1 axial noise std (metres) at depth ``z`` (metres): ``0.0012 + 0.0019 (z - 0.4)^2``.

    Nguyen, Izadi and Lovell (2012), the model our virtual Kinect uses too; it is why thresholds on real
    clouds grow with the square of the depth.
    """
    return 0.0012 + 0.0019 * (np.asarray(z, dtype=float) - 0.4) ** 2


def table_frame(
    points_cam: np.ndarray,
    *,
    table_height: float = 0.0,
    seed: int = 0,
    min_fraction: float = 0.15,
    min_camera_height: float = 0.1,
) -> TableFrame:
    """Find the table in a camera-frame cloud (metres) and the world frame it defines (see :class:`TableFrame`).

    The table is the largest plane (RANSAC on a 1 cm voxel grid, 2.5 sigma of the Kinect's depth noise at
    the cloud's median depth but at least 1 cm, seeded) among the planes whose side toward the camera holds
    most of the other points: objects stand on a table, while a wall has them in front of it but the
    camera's optical axis runs into it (rejected when it is within 30 deg of facing the camera head-on and
    a horizontal-looking plane is available). The plane is refined by least squares on its points within 3
    sigma of their own depth. :class:`UserError` when no plane holds ``min_fraction`` of the points or the
    camera is less than ``min_camera_height`` above it (then the cloud is not in a camera frame looking at
    a table: give --extrinsics, or the cloud in the world frame).
    """
    import asmteach.core  # noqa: F401  (loads libusb before open3d)

    import open3d as o3d  # isort: skip

    pts = np.asarray(points_cam, dtype=float)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) < 100:
        raise UserError(f"no table plane: the cloud has {len(pts)} valid points")
    z_med = float(np.median(pts[:, 2]))
    dist = max(0.01, 2.5 * float(depth_sigma(z_med)))
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts)).voxel_down_sample(0.01)
    rest = np.asarray(pc.points)
    o3d.utility.random.seed(int(seed))
    candidates = []
    work = pc
    for _ in range(3):
        if len(work.points) < 50:
            break
        model, inl = _plane_one_thread(o3d, work, dist)
        n = np.asarray(model[:3], dtype=float)
        d = -float(model[3])
        s = float(np.linalg.norm(n))
        n, d = n / s, d / s
        if d > 0:  # orient the normal toward the camera: the camera (origin) has n.0 - d > 0
            n, d = -n, -d
        frac = len(inl) / len(rest)
        h = rest @ n - d
        off = np.abs(h) > dist
        # Share of the points off the plane on the camera's side (objects on a table, not behind a wall).
        front = float(np.mean(h[off] > 0)) if off.any() else 1.0
        facing = float(np.degrees(np.arccos(np.clip(-n[2], -1.0, 1.0))))  # 0: the plane faces the camera
        candidates.append((frac, n, d, front, facing))
        work = work.select_by_index(inl, invert=True)
    ok = [c for c in candidates if c[0] >= min_fraction and c[3] >= 0.8]
    if not ok:
        best = max((c[0] for c in candidates), default=0.0)
        raise UserError(
            f"no table plane: the largest plane with the objects on the camera's side holds {100 * best:.0f}% of "
            f"the cloud (need {100 * min_fraction:.0f}%); give --extrinsics FILE (the camera pose) instead"
        )
    not_wall = [c for c in ok if c[4] > 30.0]
    frac, n, d, _, _ = max(not_wall or ok, key=lambda c: c[0])
    # Least squares on the full-resolution points near the plane, each within 3 sigma of its own depth.
    near = pts[np.abs(pts @ n - d) < np.maximum(3.0 * depth_sigma(pts[:, 2]), 0.005)]
    if len(near) >= 3:
        c = near.mean(axis=0)
        q = near - c
        _, vecs = np.linalg.eigh(q.T @ q)
        n2 = vecs[:, 0]
        if n2 @ n < 0:
            n2 = -n2
        n, d = n2, float(n2 @ c)
    cam_h = -d  # height of the camera (origin) above the plane along n
    if cam_h < min_camera_height:
        raise UserError(
            f"no table frame: the camera is {cam_h * 1000:.0f} mm from the largest plane; the cloud does not look "
            "like a camera-frame view of a table (give --extrinsics FILE, or a world-frame cloud with --viewpoint)"
        )
    z_w = n
    optical = np.array([0.0, 0.0, 1.0])
    x_w = optical - (optical @ z_w) * z_w
    if np.linalg.norm(x_w) < 1e-6:  # looking straight down: x is the image's up direction on the table
        up = np.array([0.0, -1.0, 0.0])
        x_w = up - (up @ z_w) * z_w
    x_w /= np.linalg.norm(x_w)
    y_w = np.cross(z_w, x_w)
    origin = -cam_h * z_w - table_height * z_w  # the foot below the camera, then down to world z = 0
    T_cam_world = np.eye(4)
    T_cam_world[:3, 0], T_cam_world[:3, 1], T_cam_world[:3, 2], T_cam_world[:3, 3] = x_w, y_w, z_w, origin
    tilt = float(np.degrees(np.arcsin(np.clip(-(optical @ z_w), -1.0, 1.0))))
    return TableFrame(geometry.invert(T_cam_world), n, d, frac, cam_h, tilt, table_height)


def _plane_one_thread(o3d: Any, pc: Any, dist: float) -> tuple[Any, list[int]]:
    """Open3D's RANSAC plane (500 iterations) on one thread: run in parallel, one seed need not give one
    plane (as Open3D's ICP and feature RANSAC did not give one pose; not traced in Open3D's source)."""
    limit = getattr(o3d.utility, "set_max_threads", None)
    if limit is None:
        return pc.segment_plane(dist, 3, 500)
    before = o3d.utility.get_max_threads()
    limit(1)
    try:
        return pc.segment_plane(dist, 3, 500)
    finally:
        limit(before)


@dataclass
class WorldCloud:
    """A cloud put in the world frame: points, the camera pose used, and how it was found."""

    points: np.ndarray
    """(n, 3) world frame, metres, NaN rows kept."""
    T_world_cam: np.ndarray
    frame: str
    """How the camera pose was found: ``extrinsics`` or ``table_plane``."""
    how: str
    """One line for the report: which camera pose was used and where it came from."""
    table: TableFrame | None = None

    @property
    def viewpoint(self) -> np.ndarray:
        """``(3,)`` camera centre, world frame, metres."""
        return self.T_world_cam[:3, 3].copy()


def to_world(
    cloud: Cloud,
    *,
    extrinsics: Extrinsics | None = None,
    table_height: float | None = None,
    seed: int = 0,
) -> WorldCloud:
    """Map a camera-frame ``cloud`` into the world (z up): with ``extrinsics`` when given, else the table plane.

    The cloud's own ``T_data_sensor`` (a PCD ``VIEWPOINT``) is undone first, so a cloud stored in some other
    frame with its sensor pose still lands in the camera frame. With the table plane the table top is at
    ``table_height`` (default 0).
    """
    pts = cloud.points
    if cloud.T_data_sensor is not None:
        pts = geometry.transform_points(geometry.invert(cloud.T_data_sensor), pts)
    if extrinsics is not None:
        T = extrinsics.T_world_cam
        how = f"camera frame -> world with the extrinsics of {extrinsics.source}"
        return WorldCloud(geometry.transform_points(T, pts), T, "extrinsics", how)
    tf = table_frame(pts, table_height=0.0 if table_height is None else table_height, seed=seed)
    how = (
        f"camera frame -> world from the table plane found in the cloud ({100 * tf.inliers:.0f}% of the points; "
        f"camera {tf.camera_height * 1000:.0f} mm above it, looking {tf.tilt_deg:.0f} deg down; table top at "
        f"z = {tf.table_height:g} m)"
    )
    return WorldCloud(geometry.transform_points(tf.T_world_cam, pts), tf.T_world_cam, "table_plane", how, tf)


def guess_frame(cloud: Cloud, *, seed: int = 0) -> tuple[Literal["camera", "world"], str]:
    """Whether ``cloud`` is in a camera frame (z forward) or already in the world (z up), and why (one line).

    The rule, cheapest test first:

    * a file that records its sensor's position (a PLY ``comment viewpoint``, a PCD ``VIEWPOINT`` other than
      the identity) is in the frame that position is given in: the world;
    * a sensor's own frame has every point in front of the camera (>= 99% with z > 0, median depth >= 0.2 m)
      *and* a table plane with the objects on the camera's side at least 0.1 m from the origin
      (:func:`table_frame`). A world-frame cloud fails one of these: its table lies near z = 0 (half its
      points below), or its origin is under the table, away from the objects.
    """
    if cloud.T_data_sensor is not None:
        return "world", "the file records its sensor's position, so its points are in the frame of that position"
    pts = cloud.valid_points()
    if len(pts) == 0:
        return "world", "no valid points"
    ahead = float(np.mean(pts[:, 2] > 0))
    median = float(np.median(pts[:, 2]))
    if ahead < 0.99 or median < 0.2:
        return "world", f"{100 * ahead:.0f}% of the points have z > 0 (median z {median:.2f} m): not a camera's view"
    try:
        tf = table_frame(pts, seed=seed)
    except UserError:
        return "world", "every point is in front of the origin, but no table plane with the objects on its near side"
    return "camera", (
        f"every point is in front of the origin (median depth {median:.2f} m) and a table plane lies "
        f"{tf.camera_height * 1000:.0f} mm from it with the objects on its side"
    )
