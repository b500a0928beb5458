"""Camera images of a PyBullet world (an OpenCV-frame pinhole camera rendered with TinyRenderer) and the
wrist camera a mount setting describes.

``T_world_cam`` is the camera pose in the world (OpenCV frame: z forward, y down, metres);
intrinsics in pixels.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pybullet
from pybullet_utils import bullet_client
from pydantic import ValidationError

from asmteach.core import geometry
from asmteach.core.arm.settings import WristCameraMount
from asmteach.core.errors import UserError
from asmteach.core.robot import WristCamera

if TYPE_CHECKING:
    from asmteach.core.perception.depth_camera import KinectSettings

__all__ = ["render_rgb", "wrist_camera_of"]


def wrist_camera_of(mount: WristCameraMount) -> WristCamera:
    """The :class:`~asmteach.core.robot.WristCamera` a mount setting describes: ``T_tcp_cam`` ``(4, 4)`` (TCP
    frame, metres; read-only) and the sensor preset with its overrides (:class:`UserError` on a bad override)."""
    from asmteach.core.perception.depth_camera import KinectSettings  # open3d loads with it: only when needed

    T = geometry.from_rpy(*np.radians(mount.rpy_deg), mount.xyz)
    T.setflags(write=False)
    preset = KinectSettings.wrist_stereo if mount.sensor == "wrist_stereo" else KinectSettings
    try:
        sensor: KinectSettings = preset(**mount.sensor_overrides)
    except ValidationError as e:
        bad = "; ".join(f"{'.'.join(str(k) for k in err['loc'])}: {err['msg']}" for err in e.errors())
        raise UserError(f"robot.settings.wrist_camera.sensor_overrides: {bad}") from None
    return WristCamera(T_tcp_cam=T, sensor=sensor)


def render_rgb(
    p: bullet_client.BulletClient,
    T_world_cam: np.ndarray,
    width: int,
    height: int,
    fx: float,
    fy: float,
    cx: float,
    cy: float,
    near: float = 0.05,
    far: float = 5.0,
) -> np.ndarray:
    """RGB image ``(h, w, 3) uint8`` with TinyRenderer from an OpenCV-frame camera pose."""
    eye = T_world_cam[:3, 3]
    fwd = T_world_cam[:3, 2]
    up = -T_world_cam[:3, 1]
    view = p.computeViewMatrix(eye.tolist(), (eye + fwd).tolist(), up.tolist())
    # OpenGL projection from the pinhole intrinsics
    proj = np.zeros((4, 4))
    proj[0, 0] = 2.0 * fx / width
    proj[1, 1] = 2.0 * fy / height
    proj[0, 2] = 1.0 - 2.0 * cx / width
    proj[1, 2] = 2.0 * cy / height - 1.0
    proj[2, 2] = -(far + near) / (far - near)
    proj[2, 3] = -2.0 * far * near / (far - near)
    proj[3, 2] = -1.0
    # No segmentation mask: only the colours are used, and TinyRenderer's mask pass costs time per frame.
    img = p.getCameraImage(
        width,
        height,
        view,
        proj.T.reshape(-1).tolist(),
        renderer=pybullet.ER_TINY_RENDERER,
        flags=pybullet.ER_NO_SEGMENTATION_MASK,
    )
    rgba = np.reshape(np.asarray(img[2], dtype=np.uint8), (height, width, 4))
    return rgba[:, :, :3].copy()
