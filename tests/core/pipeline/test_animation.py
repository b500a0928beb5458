"""write_animation: one shared palette, frames mapped onto it (colours kept, every frame written)."""

from __future__ import annotations

import types
from pathlib import Path

import numpy as np
from PIL import Image

from asmteach.core.pipeline.execute import write_animation


class _Run:
    def __init__(self, out: Path) -> None:
        self.out = out
        self.execution = types.SimpleNamespace(animation_fps=2.0)
        self.artefacts: dict[str, Path] = {}

    def artefact(self, name: str, path: Path, kind: str) -> None:
        self.artefacts[name] = path


def _frames(n: int = 6) -> list[np.ndarray]:
    """A grey table, a red and a blue block; the red one moves 8 px per frame."""
    out = []
    for k in range(n):
        f = np.full((48, 64, 3), (140, 115, 90), np.uint8)
        f[10:20, 5 + 8 * k : 15 + 8 * k] = (200, 30, 30)
        f[30:40, 40:50] = (30, 60, 210)
        out.append(f)
    return out


def test_animation_keeps_frames_and_colours(tmp_path: Path) -> None:
    frames = _frames()
    run = _Run(tmp_path)
    write_animation(run, frames)  # type: ignore[arg-type]
    gif = Image.open(run.artefacts["animation"])
    assert gif.n_frames == len(frames)
    for k, f in enumerate(frames):
        gif.seek(k)
        got = np.asarray(gif.convert("RGB")).astype(int)
        assert np.abs(got - f).max() <= 8  # three colours fit any palette: mapped (nearly) exactly
