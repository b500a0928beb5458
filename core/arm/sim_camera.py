"""Camera images of a PyBullet world: an OpenCV-frame pinhole camera rendered with TinyRenderer.

``T_world_cam`` is the camera pose in the world (OpenCV frame: z forward, y down, metres);
intrinsics in pixels.
"""

from __future__ import annotations

import numpy as np
import pybullet
from pybullet_utils import bullet_client

__all__ = ["render_rgb"]


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
