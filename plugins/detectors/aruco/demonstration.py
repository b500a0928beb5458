"""Synthetic demonstrations for simulated runs (``Teacher.demonstrate`` of the ArUco teacher).

The same renderer as ``asmteach render-demo``: the config's ``demo`` section
is validated by :class:`~asmteach.plugins.detectors.aruco.scene.DemoSettings`
(errors name ``demo.<key>``), the camera is the given intrinsics file or the
C615-like default, and the frames (BGR ``uint8``) are returned in time order.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
from pydantic import ValidationError

from asmteach.core.config import format_validation_error
from asmteach.core.errors import UserError
from asmteach.core.io import atomic_path, write_json
from asmteach.core.models import AssemblyTask, CameraIntrinsics
from asmteach.core.parts import build_part

__all__ = ["demonstrate"]


def demonstrate(
    task: AssemblyTask, demo: dict[str, Any], camera_file: Path | None, out_dir: Path | None, seed: int
) -> tuple[list[np.ndarray], CameraIntrinsics]:
    """Render the demonstration of ``task``; write frames + ``ground_truth.json`` into ``out_dir`` if given."""
    from asmteach.plugins.detectors.aruco.camera import c615_like, load_camera, save_camera
    from asmteach.plugins.detectors.aruco.scene import DemoSettings, render_demo_frames

    try:
        settings = DemoSettings.model_validate(demo)
    except ValidationError as exc:
        raise UserError(format_validation_error(exc, "demo")) from None
    camera = load_camera(camera_file) if camera_file is not None else c615_like()
    if any(abs(d) > 0 for d in camera.dist):
        raise UserError("the demonstration renderer draws an ideal pinhole camera; give intrinsics without distortion")
    a, b = build_part(task.part_a), build_part(task.part_b)
    frames: list[np.ndarray] = []
    records = []
    for fr, img, visible in render_demo_frames(a, b, task, camera, settings, seed=seed):
        frames.append(img)
        if out_dir is not None:
            name = f"frame_{fr.index:04d}.{settings.image_format}"
            Path(out_dir).mkdir(parents=True, exist_ok=True)
            with atomic_path(Path(out_dir) / name) as tmp:
                if not cv2.imwrite(str(tmp), img):
                    raise UserError(f"{Path(out_dir) / name}: cannot write the image")
            records.append(
                {
                    "file": name,
                    "phase": fr.phase,
                    "T_cam_A": fr.T_cam_A.tolist(),
                    "T_cam_B": fr.T_cam_B.tolist(),
                    "visible_markers": visible,
                }
            )
    if out_dir is not None:
        save_camera(Path(out_dir) / "camera.yaml", camera, name="demonstration")
        write_json(
            Path(out_dir) / "ground_truth.json",
            {
                "structure": task.name,
                "seed": seed,
                "demo": settings.model_dump(mode="json"),
                "T_A_B": task.T_A_B.tolist(),
                "v_a": np.asarray(task.v_a).tolist(),
                "frames": records,
            },
        )
    return frames, camera
