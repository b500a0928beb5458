"""Synthetic table scenes for the depth detectors: a part at a stable placement, seen by the Kinect.

World frame: z up, the table top at ``table.height``; the robot stands at the
origin facing +x, the table in front of it. The Kinect sits above and in
front of the table's near edge, looking down at the work area, 0.7-1.0 m from
the parts (:data:`DEFAULT_EYE`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from numpy.typing import ArrayLike

from asmteach.core import geometry
from asmteach.core.config import TableSettings
from asmteach.core.models import TablePlane
from asmteach.core.perception.depth_camera import DepthCamera, DepthFrame, look_at

__all__ = [
    "DEFAULT_EYE",
    "QUARTERS",
    "SECOND_EYE",
    "TableScene",
    "default_camera_pose",
    "place_on_table",
    "render_table_scene",
    "second_camera_pose",
    "table_mesh",
]

DEFAULT_EYE = np.array([-0.05, 0.0, 0.70])
"""Where the scene renderer puts its Kinect by default (world, metres, above the table top). Only the
renderer's default: the detectors have none, they are told the camera centre (a rendered frame carries it,
:meth:`DepthFrame.write_ply`)."""

SECOND_EYE = np.array([0.98, 0.0, 0.53])
"""The scene renderer's second Kinect (world, metres, above the table top): across the table from
:data:`DEFAULT_EYE`, looking down at the work centre at 45 deg from 0.75 m (a cell with two depth cameras)."""

WORK_CENTER = np.array([0.45, 0.0])
"""Centre of the work area on the table (world x, y, metres)."""

QUARTERS = {
    "near_right": np.array([0.35, -0.12]),
    "near_left": np.array([0.35, 0.12]),
    "far_right": np.array([0.55, -0.12]),
    "far_left": np.array([0.55, 0.12]),
}
"""Centres (world x, y, metres) of the four quarters of the work area."""


@dataclass
class TableScene:
    """A rendered scene and its ground truth."""

    frame: DepthFrame
    T_world_part: np.ndarray
    table: TablePlane

    @property
    def cloud(self) -> np.ndarray:
        """(n, 3) observed points, world frame, metres."""
        return self.frame.points_world


def default_camera_pose(table: TableSettings | None = None) -> np.ndarray:
    """``T_world_cam`` of the scene Kinect: at :data:`DEFAULT_EYE`, looking at the work centre."""
    h = table.height if table is not None else 0.0
    eye = DEFAULT_EYE + np.array([0.0, 0.0, h])
    return look_at(eye, [WORK_CENTER[0], WORK_CENTER[1], h])


def second_camera_pose(table: TableSettings | None = None, eye: ArrayLike | None = None) -> np.ndarray:
    """``T_world_cam`` of the second scene Kinect: at ``eye`` (default :data:`SECOND_EYE`; z above the table
    top), looking at the work centre."""
    h = table.height if table is not None else 0.0
    at = (SECOND_EYE if eye is None else np.asarray(eye, dtype=float)) + np.array([0.0, 0.0, h])
    return look_at(at, [WORK_CENTER[0], WORK_CENTER[1], h])


SCENE_TABLE_CENTER = (0.45, 0.0)
"""Table centre x, y of a rendered scene (world, metres) when the settings leave it to the robot."""
SCENE_TABLE_SIZE = (0.8, 1.2)
"""Table extent along x, y of a rendered scene (metres) when the settings leave it to the robot."""


def table_mesh(table: TableSettings | None = None) -> tuple[trimesh.Trimesh, np.ndarray]:
    """The table as a 2 cm slab and its ``T_world_table`` (top face at ``table.height``).

    ``table.center`` / ``table.size`` left out (``None``: the robot's own table in a run) give the
    scene's table, :data:`SCENE_TABLE_CENTER` x :data:`SCENE_TABLE_SIZE`.
    """
    t = table or TableSettings()
    cx, cy = t.center if t.center is not None else SCENE_TABLE_CENTER
    sx, sy = t.size if t.size is not None else SCENE_TABLE_SIZE
    mesh = trimesh.creation.box(extents=[sx, sy, 0.02])
    return mesh, geometry.from_rotation(np.eye(3), [cx, cy, t.height - 0.01])


def place_on_table(
    mesh: trimesh.Trimesh, T_table_part: ArrayLike, yaw: float, xy: ArrayLike, height: float = 0.0
) -> np.ndarray:
    """``T_world_part`` of a part resting in placement ``T_table_part``, turned by ``yaw`` (radians).

    The part's lowest point touches the table top (z = ``height``) and the
    centre of its bounding box (seen from above) sits at ``xy`` (metres).
    """
    T = geometry.rot_z(yaw) @ np.asarray(T_table_part, dtype=float)
    v = geometry.transform_points(T, mesh.vertices)
    lo, hi = v.min(axis=0), v.max(axis=0)
    shift = np.array([xy[0] - 0.5 * (lo[0] + hi[0]), xy[1] - 0.5 * (lo[1] + hi[1]), height - lo[2]])
    T[:3, 3] += shift
    return T


def render_table_scene(
    camera: DepthCamera,
    mesh: trimesh.Trimesh,
    T_world_part: np.ndarray,
    *,
    table: TableSettings | None = None,
    T_world_cam: np.ndarray | None = None,
    rng: np.random.Generator | None = None,
) -> TableScene:
    """Render the table and one part with ``camera`` from ``T_world_cam`` (default: the scene Kinect)."""
    t = table or TableSettings()
    slab, T_world_table = table_mesh(t)
    T_cam = default_camera_pose(t) if T_world_cam is None else T_world_cam
    frame = camera.render([(slab, T_world_table), (mesh, T_world_part)], T_cam, rng=rng)
    return TableScene(frame=frame, T_world_part=np.asarray(T_world_part, float), table=TablePlane(height=t.height))
