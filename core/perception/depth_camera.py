"""The one virtual depth camera of asmteach: a Kinect v1 model on Open3D ray casting.

Used for the 42 training views of the CVFH detector, for the test scenes of
the detection experiment and for the robot's simulated depth sensor, so all of
them see the same sensor. Frames: the camera frame is OpenCV's (x right,
y down, z forward, origin at the optical centre); poses are ``T_world_cam``
(4x4, metres). Depth is the z coordinate in the camera frame (metres).

Sensor model (each term can be switched off through :class:`KinectSettings`;
``KinectSettings.ideal()`` switches them all off):

* pinhole 640x480, fx = fy = 525 px, cx = 319.5, cy = 239.5;
* lateral noise: each pixel measures the surface seen through a ray jittered
  by ``lateral_sigma_px`` (the depth image is blurred sideways, edges wander);
* axial noise ``sigma(z) = 0.0012 + 0.0019 (z - 0.4)^2`` m (Nguyen, Izadi and
  Lovell 2012);
* disparity quantisation: the Kinect measures disparity ``b f / z`` in steps of
  ``1 / disparity_subpixel`` pixel, so depth comes in steps ``~ z^2 / (8 b f)``;
* missing returns: outside ``[min_range, max_range]``, at grazing incidence
  (dropped with a probability that rises from ``grazing_start_deg`` to
  ``grazing_end_deg``) and next to depth discontinuities (the projector's
  shadow and the stereo matcher's edge failures).

``KinectSettings.wrist_stereo()`` is the same model with a short-range active
stereo camera's figures (a RealSense D405 on the robot's wrist: 7-50 cm,
stereo noise ``~ z^2``, finer disparity steps); its docstring derives them.

Example::

    cam = DepthCamera(KinectSettings(), seed=3)
    T_world_cam = look_at(eye=[0.0, 0.0, 0.8], target=[0.45, 0.0, 0.0])
    frame = cam.render([(table_mesh, np.eye(4)), (part.mesh, T_world_part)], T_world_cam)
    frame.points_world      # (n, 3) metres, world frame
    frame.write_ply("scene.ply")   # with 'comment viewpoint X Y Z': the camera centre travels with the cloud

A cloud file tells where its camera was (:func:`asmteach.core.clouds.read_cloud`): a PLY by
the comment line ``comment viewpoint X Y Z`` (camera centre, world frame,
metres; what :func:`write_cloud_ply` writes), a PCD by its ``VIEWPOINT``
header (the translation ``tx ty tz``; PCL's default ``0 0 0 1 0 0 0``, which
every writer puts when it knows nothing, counts as no viewpoint).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from numpy.typing import ArrayLike
from pydantic import Field

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core.clouds.read import PLY_VIEWPOINT
from asmteach.core.models import CameraIntrinsics, StrictModel

import open3d as o3d  # isort: skip  (after asmteach.core)

__all__ = ["DepthCamera", "DepthFrame", "KinectSettings", "look_at", "write_cloud_ply"]


class KinectSettings(StrictModel):
    """Intrinsics and noise model of the virtual Kinect v1 (metres, pixels, degrees)."""

    width: int = Field(640, gt=0, description="image width, pixels")
    height: int = Field(480, gt=0, description="image height, pixels")
    fx: float = Field(525.0, gt=0.0, description="focal length along x, pixels")
    fy: float = Field(525.0, gt=0.0, description="focal length along y, pixels")
    cx: float = Field(319.5, description="principal point x, pixels")
    cy: float = Field(239.5, description="principal point y, pixels")
    min_range: float = Field(0.4, ge=0.0, description="nearest measurable depth, metres")
    max_range: float = Field(4.0, gt=0.0, description="farthest measurable depth, metres")
    axial_noise: bool = Field(True, description="add sigma(z) = a + b (z - z0)^2 Gaussian depth noise")
    axial_a: float = Field(0.0012, ge=0.0, description="sigma(z) constant term, metres")
    axial_b: float = Field(0.0019, ge=0.0, description="sigma(z) quadratic coefficient, 1/metres")
    axial_z0: float = Field(0.4, description="sigma(z) reference depth, metres")
    quantize: bool = Field(True, description="quantise depth as Kinect disparity")
    baseline: float = Field(0.075, gt=0.0, description="projector-camera baseline, metres")
    disparity_subpixel: int = Field(8, gt=0, description="disparity steps per pixel")
    lateral_sigma_px: float = Field(0.5, ge=0.0, description="std of the ray jitter, pixels (0: none)")
    grazing_start_deg: float = Field(70.0, ge=0.0, le=90.0, description="incidence where returns start to drop")
    grazing_end_deg: float = Field(85.0, ge=0.0, le=90.0, description="incidence beyond which no return comes")
    edge_dropout: float = Field(0.5, ge=0.0, le=1.0, description="drop probability next to a depth edge")
    edge_jump: float = Field(0.01, ge=0.0, description="depth step (metres) that counts as an edge")

    @classmethod
    def ideal(cls, **overrides: object) -> KinectSettings:
        """A noise-free camera with the same intrinsics (training views, tests)."""
        clean = dict(
            axial_noise=False,
            quantize=False,
            lateral_sigma_px=0.0,
            grazing_start_deg=90.0,
            grazing_end_deg=90.0,
            edge_dropout=0.0,
        )
        clean.update(overrides)
        return cls(**clean)

    @classmethod
    def wrist_stereo(cls, **overrides: object) -> KinectSettings:
        """A short-range active-stereo camera for a robot's wrist, modelled on an Intel RealSense D405.

        Figures (Intel's D405 datasheet): 7-50 cm range, baseline 18 mm, field of view 87 x 58 deg,
        depth error under +-2 % at 50 cm. At 640x480 the field of view gives
        ``fx = 320 / tan(43.5 deg) = 337.2`` px and ``fy = 240 / tan(29 deg) = 433.0`` px (the sensor's
        16:9 field of view on a 4:3 image: the pixels are not square).

        Axial noise is stereo's: ``sigma_z = z^2 sigma_d / (fx b)`` with a sub-pixel disparity
        error ``sigma_d = 0.08`` px (a well-textured, projector-lit surface), so ``axial_b =
        0.08 / (337.2 * 0.018) = 0.0132`` 1/m, ``axial_z0 = 0`` and ``axial_a = 0`` (no floor:
        the quantisation below dominates near 7 cm): sigma 0.13 mm at 0.1 m, 1.19 mm at 0.3 m,
        3.30 mm at 0.5 m (+-2 % at 50 cm is 10 mm, three sigma). Quantisation: disparity
        ``b fx / z`` in 1/32 px steps (the D4 processor's 5 sub-pixel bits), depth steps
        ``z^2 / (32 b fx)``: 0.05 mm at 0.1 m, 0.46 mm at 0.3 m, 1.29 mm at 0.5 m.
        Lateral jitter, grazing and edge dropouts are the Kinect's (the stereo matcher fails
        on stretched texture and at occlusion edges as the Kinect's does).
        """
        fov_x, fov_y, width, height = np.radians(87.0), np.radians(58.0), 640, 480
        fx = 0.5 * width / np.tan(0.5 * fov_x)
        fy = 0.5 * height / np.tan(0.5 * fov_y)
        baseline, sigma_disparity_px = 0.018, 0.08
        preset: dict[str, object] = dict(
            width=width,
            height=height,
            fx=float(fx),
            fy=float(fy),
            cx=0.5 * width - 0.5,
            cy=0.5 * height - 0.5,
            min_range=0.07,
            max_range=0.5,
            axial_a=0.0,
            axial_b=float(sigma_disparity_px / (fx * baseline)),
            axial_z0=0.0,
            baseline=baseline,
            disparity_subpixel=32,
        )
        preset.update(overrides)
        return cls(**preset)

    @property
    def K(self) -> np.ndarray:
        """``(3, 3)`` camera matrix, pixels."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def intrinsics(self) -> CameraIntrinsics:
        """The pinhole model as :class:`CameraIntrinsics` (no distortion)."""
        return CameraIntrinsics(K=self.K, width=self.width, height=self.height)

    def axial_sigma(self, z: np.ndarray) -> np.ndarray:
        """Axial noise std (metres) at depth ``z`` (metres)."""
        return self.axial_a + self.axial_b * (np.asarray(z) - self.axial_z0) ** 2


@dataclass
class DepthFrame:
    """One rendered depth frame.

    ``depth`` is ``(h, w)`` metres with NaN where the sensor gave no return;
    ``points_cam`` and ``points_world`` are the ``(n, 3)`` valid pixels
    back-projected to the camera and world frames; ``pixels`` are their
    ``(n, 2)`` int ``(row, col)``; ``labels`` the ``(n,)`` index of the mesh
    (in the list given to :meth:`DepthCamera.render`) each pixel saw.
    """

    depth: np.ndarray
    points_cam: np.ndarray
    points_world: np.ndarray
    pixels: np.ndarray
    labels: np.ndarray
    T_world_cam: np.ndarray

    @property
    def viewpoint(self) -> np.ndarray:
        """``(3,)`` camera centre, world frame, metres."""
        return self.T_world_cam[:3, 3].copy()

    def write_ply(self, path: str | Path) -> Path:
        """Write ``points_world`` as a PLY that carries the camera centre (see :func:`write_cloud_ply`)."""
        return write_cloud_ply(path, self.points_world, self.viewpoint)


def write_cloud_ply(path: str | Path, points: ArrayLike, viewpoint: ArrayLike | None = None) -> Path:
    """Write ``(n, 3)`` points (world frame, metres) as a binary PLY, with ``comment viewpoint X Y Z`` if given.

    Open3D, PCL and MeshLab read it; the comment is how the camera centre
    reaches ``asmteach detect`` (:func:`asmteach.core.clouds.read_cloud`).
    """
    pts = np.asarray(points, dtype="<f4").reshape(-1, 3)
    lines = ["ply", "format binary_little_endian 1.0"]
    if viewpoint is not None:
        eye = np.asarray(viewpoint, dtype=float).reshape(3)
        lines.append(f"{PLY_VIEWPOINT} " + " ".join(repr(float(v)) for v in eye))
    lines += [f"element vertex {len(pts)}", "property float x", "property float y", "property float z", "end_header"]
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_bytes(("\n".join(lines) + "\n").encode("ascii") + pts.tobytes())
    return out


def look_at(eye: ArrayLike, target: ArrayLike, up: ArrayLike = (0.0, 0.0, 1.0)) -> np.ndarray:
    """``T_world_cam`` (4x4) of a camera at ``eye`` looking at ``target`` (world, metres).

    The camera frame is OpenCV's: z toward the target, x right, y down in the
    image, with the image's "up" as close to ``up`` as possible. Raises
    ``ValueError`` when ``eye == target`` or the view axis is parallel to ``up``
    (pass another ``up`` then).
    """
    eye = np.asarray(eye, dtype=float)
    z = np.asarray(target, dtype=float) - eye
    if np.linalg.norm(z) < 1e-9:
        raise ValueError("look_at: eye and target coincide")
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, dtype=float))
    if np.linalg.norm(x) < 1e-6:
        raise ValueError("look_at: the view direction is parallel to up; give another up vector")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, eye
    return T


class DepthCamera:
    """Renders meshes at world poses to Kinect-like depth frames.

    ``seed`` makes the noise reproducible: the ``i``-th call to
    :meth:`render` of two cameras built with the same settings and seed gives
    the same frame. Pass ``rng`` to :meth:`render` to draw from your own
    generator instead.
    """

    def __init__(self, settings: KinectSettings | None = None, seed: int = 0) -> None:
        self.settings = settings or KinectSettings()
        self._rng = np.random.default_rng(seed)
        s = self.settings
        v, u = np.mgrid[0 : s.height, 0 : s.width]
        self._u = u.astype(np.float64)
        self._v = v.astype(np.float64)

    def render(
        self,
        meshes: Sequence[tuple[trimesh.Trimesh, ArrayLike]],
        T_world_cam: ArrayLike,
        *,
        rng: np.random.Generator | None = None,
    ) -> DepthFrame:
        """Render ``[(mesh, T_world_mesh), ...]`` (mesh vertices in metres) seen from ``T_world_cam``."""
        s = self.settings
        rng = rng if rng is not None else self._rng
        T_wc = np.asarray(T_world_cam, dtype=float)
        T_cw = np.linalg.inv(T_wc)
        scene = o3d.t.geometry.RaycastingScene()
        for mesh, T_wm in meshes:
            # Meshes go in camera coordinates so rays start at the origin.
            T_cm = T_cw @ np.asarray(T_wm, dtype=float)
            verts = np.asarray(mesh.vertices, dtype=float) @ T_cm[:3, :3].T + T_cm[:3, 3]
            scene.add_triangles(
                o3d.core.Tensor(verts.astype(np.float32)),
                o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)),
            )

        u, v = self._u, self._v
        if s.lateral_sigma_px > 0:
            # Each pixel measures the surface a little beside where it looks.
            u = u + rng.normal(0.0, s.lateral_sigma_px, u.shape)
            v = v + rng.normal(0.0, s.lateral_sigma_px, v.shape)
        # Directions with unit z: the hit distance is then the depth itself.
        dirs = np.stack([(u - s.cx) / s.fx, (v - s.cy) / s.fy, np.ones_like(u)], axis=-1)
        rays = np.concatenate([np.zeros_like(dirs), dirs], axis=-1).astype(np.float32)
        hit = scene.cast_rays(o3d.core.Tensor(rays))
        depth = hit["t_hit"].numpy().astype(np.float64)
        labels_img = hit["geometry_ids"].numpy().astype(np.int64)
        normals = hit["primitive_normals"].numpy().astype(np.float64)
        valid = np.isfinite(depth)

        # Grazing incidence: the projected pattern is too stretched to match.
        if s.grazing_start_deg < 90.0:
            unit = dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)
            cos_inc = np.abs(np.sum(unit * normals, axis=-1))
            inc = np.degrees(np.arccos(np.clip(cos_inc, 0.0, 1.0)))
            span = max(s.grazing_end_deg - s.grazing_start_deg, 1e-9)
            p_drop = np.clip((inc - s.grazing_start_deg) / span, 0.0, 1.0)
            valid &= rng.random(depth.shape) >= p_drop

        # Depth edges: the matcher fails on windows that straddle a jump.
        if s.edge_dropout > 0:
            edge = _edge_mask(np.where(np.isfinite(depth), depth, np.inf), s.edge_jump)
            valid &= ~(edge & (rng.random(depth.shape) < s.edge_dropout))

        z = np.where(valid, depth, np.nan)
        if s.axial_noise:
            z = z + rng.normal(0.0, 1.0, z.shape) * s.axial_sigma(np.nan_to_num(z, nan=s.axial_z0))
        if s.quantize:
            bf = s.baseline * s.fx
            disparity = np.round(bf / z * s.disparity_subpixel) / s.disparity_subpixel
            z = bf / disparity
        z[(z < s.min_range) | (z > s.max_range) | ~np.isfinite(z)] = np.nan

        rows, cols = np.nonzero(np.isfinite(z))
        zz = z[rows, cols]
        # Back-project at the nominal pixel centre: that is all a real sensor reports.
        pts_cam = np.stack([(cols - s.cx) / s.fx * zz, (rows - s.cy) / s.fy * zz, zz], axis=-1)
        pts_world = pts_cam @ T_wc[:3, :3].T + T_wc[:3, 3]
        return DepthFrame(
            depth=z,
            points_cam=pts_cam,
            points_world=pts_world,
            pixels=np.stack([rows, cols], axis=-1),
            labels=labels_img[rows, cols],
            T_world_cam=T_wc,
        )


def _edge_mask(depth: np.ndarray, jump: float) -> np.ndarray:
    """Pixels whose 4-neighbourhood holds a depth more than ``jump`` metres away (inf = background)."""
    d = depth
    edge = np.zeros(d.shape, dtype=bool)
    with np.errstate(invalid="ignore"):
        dy = np.abs(d[1:, :] - d[:-1, :])
        dx = np.abs(d[:, 1:] - d[:, :-1])
    big_y = ~(dy <= jump)  # inf - inf is NaN: background next to background is no edge
    big_x = ~(dx <= jump)
    both_inf_y = np.isinf(d[1:, :]) & np.isinf(d[:-1, :])
    both_inf_x = np.isinf(d[:, 1:]) & np.isinf(d[:, :-1])
    big_y &= ~both_inf_y
    big_x &= ~both_inf_x
    edge[1:, :] |= big_y
    edge[:-1, :] |= big_y
    edge[:, 1:] |= big_x
    edge[:, :-1] |= big_x
    return edge
