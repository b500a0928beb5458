"""Reading demonstration frames from an image folder or a video file."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from asmteach.core.errors import UserError

__all__ = ["IMAGE_SUFFIXES", "load_frames", "load_named_frames"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def load_frames(path: str | Path, *, max_frames: int | None = None) -> list[np.ndarray]:
    """BGR ``uint8`` frames of a folder of images (sorted by name) or of a video file, in time order."""
    return [img for _, img in load_named_frames(path, max_frames=max_frames)]


def load_named_frames(path: str | Path, *, max_frames: int | None = None) -> list[tuple[str, np.ndarray]]:
    """Like :func:`load_frames`, each frame with its name: the file name, or ``"frame <k>"`` of a video."""
    p = Path(path)
    if p.is_dir():
        files = sorted(f for f in p.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise UserError(f"{p}: the folder holds no images ({', '.join(IMAGE_SUFFIXES)})")
        named = []
        for f in files[:max_frames]:
            img = cv2.imread(str(f), cv2.IMREAD_COLOR)
            if img is None:
                raise UserError(f"{f}: cannot read the image (corrupt or not an image)")
            named.append((f.name, img))
        return named
    if not p.exists():
        raise UserError(f"{p}: no such folder or video file")
    cap = cv2.VideoCapture(str(p))
    try:
        if not cap.isOpened():
            raise UserError(f"{p}: cannot open the video (unknown format or codec); give a folder of images instead")
        frames = []
        while max_frames is None or len(frames) < max_frames:
            ok, img = cap.read()
            if not ok:
                break
            frames.append(img)
    finally:
        cap.release()
    if not frames:
        raise UserError(f"{p}: the video holds no readable frames")
    return [(f"frame {k}", img) for k, img in enumerate(frames)]
