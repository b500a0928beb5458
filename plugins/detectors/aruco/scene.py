"""Synthetic demonstrations: where the parts are in each frame, and the camera effects.

A demonstration is a hand-held approach of B into A along ``v_a`` followed by
frames of the assembled pair held still (with hand tremor). The assembly is
seen from one of five viewing directions per structure, chosen so that both
parts show markers. Frames get uneven lighting, hand-like occluders that never
hide every marker of a part, motion blur, sensor noise and JPEG compression.
All randomness flows from the seed given.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np
from pydantic import Field

from asmteach.core import geometry
from asmteach.core.interfaces import PartModel
from asmteach.core.models import AssemblyTask, CameraIntrinsics, StrictModel
from asmteach.plugins.detectors.aruco.render import Rendered, RenderObject, render_scene
from asmteach.plugins.detectors.aruco.views import assembly_centre, choose_views, usable_markers

__all__ = ["DemoFrame", "DemoSettings", "demo_poses", "render_demo_frames"]


class DemoSettings(StrictModel):
    """The ``demo`` section of a run config (``asmteach render-demo``)."""

    orientation: int = Field(0, ge=0, le=4, description="which of the structure's five viewing orientations")
    distance: float = Field(0.45, ge=0.2, le=1.2, description="camera to assembly centre, metres")
    frames: int = Field(30, ge=1, le=2000, description="frames of the assembled pair")
    approach_frames: int = Field(12, ge=0, le=500, description="frames of B approaching A before assembly")
    approach_length: float = Field(0.06, gt=0.0, le=0.5, description="distance B travels along v_a, metres")
    approach_wobble: float = Field(0.0003, ge=0.0, le=0.01, description="lateral wobble of the approach, metres")
    tremor_m: float = Field(0.003, ge=0.0, le=0.05, description="hand tremor amplitude (translation), metres")
    tremor_deg: float = Field(2.0, ge=0.0, le=30.0, description="hand tremor amplitude (rotation), degrees")
    noise_sigma: float = Field(2.0, ge=0.0, le=50.0, description="sensor noise std, grey levels (0-255)")
    blur_px: float = Field(1.0, ge=0.0, le=20.0, description="max motion-blur length of still frames, pixels")
    approach_blur_px: float = Field(2.5, ge=0.0, le=30.0, description="max motion-blur length while moving")
    jpeg_quality: int = Field(90, ge=10, le=100, description="JPEG quality of the written frames")
    lighting: float = Field(0.35, ge=0.0, le=0.9, description="strength of the uneven illumination (0: even)")
    hands: int = Field(2, ge=0, le=4, description="hand-like occluders per frame")
    supersample: int = Field(4, ge=1, le=8, description="samples per pixel side (anti-aliasing)")
    image_format: Literal["jpg", "png"] = Field("jpg", description="file format of the written frames")


@dataclass
class DemoFrame:
    """Ground truth of one frame."""

    index: int
    phase: Literal["approach", "assembled"]
    T_cam_A: np.ndarray
    T_cam_B: np.ndarray


def _smooth_noise(rng: np.random.Generator, n: int, dims: int, amplitude: float) -> np.ndarray:
    """``(n, dims)`` smooth random signal (sum of a few random sinusoids), peak about ``amplitude``."""
    t = np.arange(n)[:, None]
    out = np.zeros((n, dims))
    for _ in range(3):
        freq = rng.uniform(0.02, 0.15, size=dims)
        phase = rng.uniform(0, 2 * np.pi, size=dims)
        out += np.sin(2 * np.pi * freq * t + phase) / 3.0
    return amplitude * out


def demo_poses(
    task: AssemblyTask, T_cam_A0: np.ndarray, centre: np.ndarray, settings: DemoSettings, rng: np.random.Generator
) -> list[DemoFrame]:
    """Ground-truth poses: approach frames, then assembled frames with hand tremor.

    Tremor moves the whole assembly about its centre; B stays rigidly at
    ``T_A_B`` in the assembled frames. In approach frames B is at ``T_A_B``
    moved back by ``s * v_a`` (A's frame), ``s`` falling linearly to one step
    before contact, plus a small lateral wobble.
    """
    n = settings.approach_frames + settings.frames
    trem_t = _smooth_noise(rng, n, 3, settings.tremor_m)
    trem_r = _smooth_noise(rng, n, 3, np.radians(settings.tremor_deg))
    v = np.asarray(task.v_a, float)
    frames: list[DemoFrame] = []
    to_c, from_c = geometry.from_rotation(np.eye(3), -centre), geometry.from_rotation(np.eye(3), centre)
    for i in range(n):
        wobble = geometry.from_rotvec(trem_r[i], trem_t[i])
        T_cam_A = T_cam_A0 @ from_c @ wobble @ to_c
        if i < settings.approach_frames:
            s = settings.approach_length * (settings.approach_frames - i) / settings.approach_frames
            lateral = rng.normal(0.0, settings.approach_wobble, 3)
            lateral -= lateral.dot(v) * v
            T_A_B = task.T_A_B.copy()
            T_A_B[:3, 3] += -s * v + lateral
            phase: Literal["approach", "assembled"] = "approach"
        else:
            T_A_B = task.T_A_B
            phase = "assembled"
        frames.append(DemoFrame(index=i, phase=phase, T_cam_A=T_cam_A, T_cam_B=T_cam_A @ T_A_B))
    return frames


def _background(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """A smooth, textured backdrop (float RGB)."""
    base = rng.uniform(0.25, 0.6, size=3)
    coarse = rng.normal(0.0, 0.06, size=(9, 16, 3)).astype(np.float32)
    field = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)
    return np.clip(base[None, None, :] + field, 0.0, 1.0).astype(np.float32)


def _lighting(rng: np.random.Generator, h: int, w: int, strength: float) -> np.ndarray:
    """Multiplicative illumination field: a linear ramp and a soft spot, mean about 1."""
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    ang = rng.uniform(0, 2 * np.pi)
    ramp = np.cos(ang) * (xx / w - 0.5) + np.sin(ang) * (yy / h - 0.5)
    cx, cy = rng.uniform(0.2, 0.8) * w, rng.uniform(0.2, 0.8) * h
    spot = np.exp(-(((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * (0.35 * w) ** 2)))
    return (1.0 + strength * (ramp + 0.6 * (spot - 0.5))).astype(np.float32)


def _hand_polygons(rng: np.random.Generator, centre_px: np.ndarray, scale_px: float) -> list[np.ndarray]:
    """A palm and four fingers as polygons (image pixels) around ``centre_px``."""
    ang = rng.uniform(0, 2 * np.pi)
    palm_r = scale_px * rng.uniform(0.45, 0.6)
    c = centre_px + scale_px * rng.uniform(0.9, 1.4) * np.array([np.cos(ang), np.sin(ang)])
    polys = [
        np.array(
            cv2.ellipse2Poly(
                (int(c[0]), int(c[1])), (int(palm_r), int(0.8 * palm_r)), int(np.degrees(ang)), 0, 360, 10
            ),
            np.float64,
        )
    ]
    toward = -np.array([np.cos(ang), np.sin(ang)])
    side = np.array([-toward[1], toward[0]])
    for k in range(4):
        base = c + toward * 0.7 * palm_r + side * (k - 1.5) * 0.42 * palm_r
        length = palm_r * rng.uniform(0.6, 1.1)
        tip = base + toward * length
        wdt = 0.17 * palm_r
        polys.append(np.array([base - side * wdt, tip - side * wdt, tip + side * wdt, base + side * wdt]))
    return polys


def _motion_blur(img: np.ndarray, length: float, angle: float) -> np.ndarray:
    """Linear motion blur centred on the pixel (no shift of the image)."""
    if length < 0.5:
        return img
    size = int(np.ceil(length)) | 1
    size = max(size, 3)
    kernel = np.zeros((size * 8 + 1, size * 8 + 1), np.float32)
    c = size * 4
    d = np.array([np.cos(angle), np.sin(angle)]) * length * 4
    cv2.line(
        kernel,
        (round(c - d[0] / 2), round(c - d[1] / 2)),
        (round(c + d[0] / 2), round(c + d[1] / 2)),
        1.0,
        1,
        cv2.LINE_AA,
    )
    kernel = cv2.resize(kernel, (size * 2 + 1, size * 2 + 1), interpolation=cv2.INTER_AREA)
    kernel = 0.5 * (kernel + kernel[::-1, ::-1])  # exactly symmetric: blur must not shift edges
    kernel /= kernel.sum()
    return cv2.filter2D(img, -1, kernel, borderType=cv2.BORDER_REFLECT)


def render_demo_frames(
    a: PartModel, b: PartModel, task: AssemblyTask, camera: CameraIntrinsics, settings: DemoSettings, seed: int
):
    """Yield ``(DemoFrame, uint8 BGR image, visible marker ids)`` for the whole demonstration."""
    rng = np.random.default_rng([seed, settings.orientation, 7001])
    approach = settings.approach_length if settings.approach_frames > 0 else 0.0
    views = choose_views(a, b, task, camera, settings.distance, approach_length=approach)
    T_cam_A0 = views[settings.orientation]
    centre = assembly_centre(a, b, task.T_A_B)
    frames = demo_poses(task, T_cam_A0, centre, settings, rng)
    h, w = camera.height, camera.width
    background = _background(rng, h, w)
    light_field = _lighting(rng, h, w, settings.lighting)
    light_dir = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.8, -0.2), -1.0])
    ids = {"A": [m.id for m in a.spec.markers], "B": [m.id for m in b.spec.markers]}
    f = float(camera.K[0, 0])
    light3 = cv2.merge([light_field] * 3)
    noise = np.empty((h, w, 3), np.float32)
    var0, var1 = np.float32(settings.noise_sigma) ** 2 * np.float32([0.3, 0.7 / 255.0])
    for fr in frames:
        r: Rendered = render_scene(
            [
                RenderObject(a.mesh, a.spec.color, a.spec.markers, fr.T_cam_A),
                RenderObject(b.mesh, b.spec.color, b.spec.markers, fr.T_cam_B),
            ],
            camera.K,
            w,
            h,
            background=background,
            light_dir_cam=tuple(light_dir),
            supersample=settings.supersample,
        )
        img = cv2.multiply(r.image, light3)
        visible = _add_hands(img, r, fr, ids, settings.hands, f, camera, rng)
        blur = settings.approach_blur_px if fr.phase == "approach" else settings.blur_px
        img = _motion_blur(img, rng.uniform(0.0, blur), rng.uniform(0, np.pi))
        lin = np.clip(img, 0.0, 1.0, out=img)
        lin *= np.float32(255.0)
        # Shot noise grows with brightness; read noise is constant. OpenCV's generator (seeded from ours) draws
        # the million normals of a frame three times faster than numpy's.
        sigma = cv2.sqrt(cv2.addWeighted(lin, float(var1), lin, 0.0, float(var0)))
        cv2.setRNGSeed(int(rng.integers(2**31)))
        cv2.randn(noise, 0.0, 1.0)
        lin += cv2.multiply(noise, sigma)
        lin += np.float32(0.5)
        out = np.empty((h, w, 3), np.uint8)
        np.copyto(out, np.clip(lin, 0, 255, out=lin), casting="unsafe")
        out = cv2.cvtColor(out, cv2.COLOR_RGB2BGR)
        if settings.image_format == "jpg":
            _ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, settings.jpeg_quality])
            out = cv2.imdecode(buf, cv2.IMREAD_COLOR)
        yield fr, np.ascontiguousarray(out), visible


def _add_hands(
    img: np.ndarray,
    r: Rendered,
    fr: DemoFrame,
    ids: dict[str, list[int]],
    count: int,
    f: float,
    camera: CameraIntrinsics,
    rng: np.random.Generator,
) -> list[int]:
    """Draw up to ``count`` hands (in place) so each part keeps a fully visible marker; return visible ids."""
    mask = r.marker_mask
    assert mask is not None
    x0, y0, x1, y1 = r.roi
    roi_mask = mask[y0:y1, x0:x1]
    # Pixels of each marker a detector can use (unoccluded by the parts, not seen edge-on): a marker seen at a
    # grazing angle must not count as the one a hand leaves visible.
    pixels = {i: np.flatnonzero(roi_mask == i) for i in usable_markers(r)}

    def visible_ids(cover: np.ndarray) -> set[int]:
        c = cover[y0:y1, x0:x1].ravel()
        return {i for i, px in pixels.items() if len(px) and not c[px].any()}

    cover = np.zeros(mask.shape, np.uint8)
    for _role, T in (("A", fr.T_cam_A), ("B", fr.T_cam_B)):
        if count <= 0:
            break
        centre = camera.K @ T[:3, 3]
        centre_px = centre[:2] / centre[2]
        scale = f * 0.06 / T[2, 3]  # a palm is about 6 cm
        for _ in range(6):
            polys = _hand_polygons(rng, centre_px, scale)
            trial = cover.copy()
            cv2.fillPoly(trial, [np.round(p).astype(np.int32) for p in polys], 1)
            vis = visible_ids(trial)
            if any(i in vis for i in ids["A"]) and any(i in vis for i in ids["B"]):
                cover = trial
                skin = np.array([0.87, 0.68, 0.55]) * rng.uniform(0.8, 1.05)
                allp = np.vstack(polys)
                bx0, by0 = np.clip(np.floor(allp.min(axis=0)).astype(int) - 2, 0, None)
                bx1, by1 = np.ceil(allp.max(axis=0)).astype(int) + 3
                bx1, by1 = min(bx1, img.shape[1]), min(by1, img.shape[0])
                if bx1 > bx0 and by1 > by0:
                    alpha = np.zeros((by1 - by0, bx1 - bx0), np.float32)
                    pts = [np.round((p - [bx0, by0]) * 16).astype(np.int32) for p in polys]
                    cv2.fillPoly(alpha, pts, 1.0, lineType=cv2.LINE_AA, shift=4)
                    patch = img[by0:by1, bx0:bx1]
                    patch += alpha[..., None] * (skin.astype(np.float32) - patch)
                break
        count -= 1
    return sorted(visible_ids(cover))
