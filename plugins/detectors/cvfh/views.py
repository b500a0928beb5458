"""The 42-view database of a part: rendered views, their CVFH regions and CRHs.

Views (paper, "Rough detection using point cloud"): the virtual depth camera
sits on the 42 vertices of a once-subdivided icosphere around the part
(``trimesh.creation.icosphere(subdivisions=1)``), ``distance`` metres from the
part's bounding-box centre, looking at it. Each view's cloud is described in
its *aligned camera frame*: the camera frame rotated about the optical centre
so that the cloud's centroid lies on the +z axis. Scene clusters are
described in the same kind of frame, so a view and a matching cluster differ
by a roll about z (found with CRH) and a shift along z. Rotating about the
optical centre keeps the viewpoint at the origin, which CVFH needs.

The database is built once per part and cached on disk as ``.npz``, keyed by
the mesh hash and every setting that changes its content, and written
atomically (two processes building it at once both end with a valid file).
"""

from __future__ import annotations

import hashlib
import json
import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from pydantic import Field

from asmteach.core import geometry
from asmteach.core.errors import UserError
from asmteach.core.io import atomic_path, cache_root
from asmteach.core.models import StrictModel
from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings, look_at
from asmteach.core.perception.segmentation import to_o3d

__all__ = [
    "DB_VERSION",
    "CloudDescription",
    "DescriptorSettings",
    "ViewDatabase",
    "ViewSettings",
    "align_to_z",
    "build_views",
    "default_cache_dir",
    "describe_cloud",
    "load_or_build",
    "normalize_hist",
]

log = logging.getLogger(__name__)

DB_VERSION = 1
"""Bumped whenever the database content changes for the same settings."""

# CVFH histogram blocks: f1 | f2 | f3 | centroid distance | viewpoint.
_BLOCKS = ((0, 45), (45, 90), (90, 135), (135, 180), (180, 308))


class DescriptorSettings(StrictModel):
    """How a cloud is described (the same for views and scene clusters; metres)."""

    voxel: float = Field(0.003, gt=0.0, description="voxel size the cloud is reduced to before description")
    normal_radius: float = Field(0.015, gt=0.0, description="radius of the normal / curvature estimation")
    min_points: int = Field(30, ge=5, description="fewer points than this cannot be described")


class ViewSettings(StrictModel):
    """The training views."""

    distance: float = Field(0.8, gt=0.0, description="camera distance from the part centre, metres")
    noisy: bool = Field(
        True,
        description="render views with the Kinect noise model (else an ideal camera); noisy views match noisy "
        "scenes better (measured: 94% vs 75% of scenes get a hypothesis within 25 deg from the 10 nearest views)",
    )
    seed: int = Field(0, ge=0, description="noise seed of noisy views")
    cache_dir: str | None = Field(None, description="database folder; default cvfh_views in asmteach's cache root")


@dataclass
class CloudDescription:
    """Descriptors of one cloud given in an aligned camera frame (centroid on +z)."""

    points: np.ndarray
    """(n, 3) the reduced cloud, metres."""
    centroid: np.ndarray
    """(3,) its centroid (on the +z axis)."""
    hists: np.ndarray
    """(r, 308) block-normalised CVFH histograms, one per smooth region."""
    region_centroids: np.ndarray
    """(r, 3) region centroids."""
    crh: np.ndarray | None
    """(90,) camera roll histogram about +z (PCL layout); None when the roll is undefined."""


@dataclass
class ViewDatabase:
    """Descriptors of the 42 views of one part.

    ``T_acam_part[i]`` is the part's pose in view ``i``'s aligned camera frame;
    region ``j`` belongs to view ``region_view[j]``.
    """

    key: str
    T_acam_part: np.ndarray
    """(42, 4, 4)"""
    centroids: np.ndarray
    """(42, 3) view-cloud centroids in their aligned frames (x = y = 0)."""
    crh: np.ndarray
    """(42, 90); all zeros where the view's roll is undefined (a face seen head-on)."""
    hists: np.ndarray
    """(R, 308) region histograms of all views."""
    region_view: np.ndarray
    """(R,) int view index of each region."""
    region_centroids: np.ndarray
    """(R, 3)"""
    view_dirs: np.ndarray
    """(42, 3) unit directions, part frame, from the part centre toward each camera."""

    def save(self, path: Path) -> Path:
        """Write the database atomically as ``.npz``."""
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, key=np.array(self.key), **{k: getattr(self, k) for k in _ARRAYS})
        return path

    @classmethod
    def load(cls, path: Path) -> ViewDatabase:
        """Read a database written by :meth:`save`."""
        with np.load(path, allow_pickle=False) as z:
            db = cls(key=str(z["key"]), **{k: z[k] for k in _ARRAYS})
        n_regions = len(db.hists)
        if db.hists.ndim != 2 or len(db.region_view) != n_regions or len(db.region_centroids) != n_regions:
            raise ValueError("the arrays do not fit together")
        # A view too small to describe is left out with a NaN centroid and no region (build_views): only the
        # described views' centroids must be finite. Rejecting every NaN rebuilt such a part's database on
        # every load (ff_lower_leg3 of the corpus, 8 of its 42 views left out).
        left_out = ~np.isin(np.arange(len(db.centroids)), db.region_view)
        if not np.all(np.isfinite(db.centroids[~left_out])) or not all(
            np.all(np.isfinite(getattr(db, k))) for k in _ARRAYS if k != "centroids"
        ):
            raise ValueError("the arrays hold NaN")
        return db


_ARRAYS = ("T_acam_part", "centroids", "crh", "hists", "region_view", "region_centroids", "view_dirs")


def default_cache_dir() -> Path:
    """``cvfh_views`` in :func:`asmteach.core.io.cache_root` (``$ASMTEACH_CACHE_DIR``, ``$XDG_CACHE_HOME``)."""
    return cache_root() / "cvfh_views"


def normalize_hist(h: np.ndarray) -> np.ndarray:
    """Each CVFH block scaled to sum 1, so clouds of different density compare."""
    out = np.array(h, dtype=float, copy=True)
    for a, b in _BLOCKS:
        s = out[..., a:b].sum(axis=-1, keepdims=True)
        out[..., a:b] /= np.where(s > 0, s, 1.0)
    return out


def align_to_z(c: np.ndarray) -> np.ndarray:
    """``(3, 3)`` minimal rotation taking direction ``c`` onto +z."""
    a = np.asarray(c, dtype=float) / np.linalg.norm(c)
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(a, z)
    s = float(np.linalg.norm(axis))
    if s < 1e-12:
        return np.eye(3) if a[2] > 0 else np.diag([1.0, -1.0, -1.0])
    angle = float(np.arctan2(s, a @ z))
    return geometry.from_rotvec(axis / s * angle)[:3, :3]


def describe_cloud(
    points: np.ndarray, s: DescriptorSettings, lap: Callable[[str], None] | None = None
) -> CloudDescription | None:
    """Reduce and describe a cloud given in an aligned camera frame; ``None`` when too small.

    The viewpoint is the origin. Normals come from the descriptors package
    (oriented toward the origin). ``lap`` (e.g. :meth:`StageClock.lap`) is called with ``"normals"`` once the
    voxel grid and the normals are done, so a caller can time them apart from the descriptors.
    """
    from asmteach.plugins.detectors.cvfh.descriptors import (
        compute_crh,
        compute_cvfh,
        estimate_normals_curvature,
    )

    pts = np.asarray(to_o3d(points).voxel_down_sample(s.voxel).points)
    if len(pts) < s.min_points:
        return None
    normals, curv = estimate_normals_curvature(pts, s.normal_radius, np.zeros(3))
    ok = np.all(np.isfinite(normals), axis=1) & np.isfinite(curv)  # isolated points get no normal
    pts, normals, curv = pts[ok], normals[ok], curv[ok]
    if lap is not None:
        lap("normals")
    if len(pts) < s.min_points:
        return None
    try:
        regions = compute_cvfh(pts, normals, curv)
    except UserError:
        return None
    if not regions:
        return None
    centroid = pts.mean(axis=0)
    try:
        crh: np.ndarray | None = np.asarray(compute_crh(pts, normals, centroid), dtype=float)
    except UserError:
        crh = None  # every normal along the view axis (one face seen head-on): the roll is undefined
    if crh is not None and not np.all(np.isfinite(crh)):
        crh = None
    return CloudDescription(
        points=pts,
        centroid=centroid,
        hists=normalize_hist(np.stack([np.asarray(r.hist, dtype=float) for r in regions])),
        region_centroids=np.stack([np.asarray(r.centroid, dtype=float) for r in regions]),
        crh=crh,
    )


def _view_up(direction: np.ndarray) -> np.ndarray:
    """An up vector not parallel to the view direction."""
    return np.array([0.0, 0.0, 1.0]) if abs(direction[2]) < 0.9 else np.array([0.0, 1.0, 0.0])


def build_views(
    mesh: trimesh.Trimesh,
    views: ViewSettings,
    desc: DescriptorSettings,
    camera: KinectSettings,
    key: str = "",
) -> ViewDatabase:
    """Render and describe the 42 icosphere views of ``mesh`` (part frame, metres)."""
    center = np.asarray(mesh.bounds).mean(axis=0)
    dirs = np.asarray(trimesh.creation.icosphere(subdivisions=1).vertices, dtype=float)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    cam = DepthCamera(camera if views.noisy else KinectSettings.ideal(**_intrinsics(camera)), seed=views.seed)
    T_acam, cents, crhs, hists, rview, rcent = [], [], [], [], [], []
    for i, d in enumerate(dirs):
        T_part_cam = look_at(center + views.distance * d, center, _view_up(d))
        frame = cam.render([(mesh, np.eye(4))], T_part_cam)
        A = np.eye(4)
        if len(frame.points_cam):
            A[:3, :3] = align_to_z(frame.points_cam.mean(axis=0))
        described = describe_cloud(frame.points_cam @ A[:3, :3].T, desc) if len(frame.points_cam) else None
        T_acam.append(A @ geometry.invert(T_part_cam))
        if described is None:
            log.warning("view %d of the part shows too few points to describe; it is left out", i)
            cents.append(np.full(3, np.nan))
            crhs.append(np.zeros(90))
            continue
        cents.append(described.centroid)
        crhs.append(described.crh if described.crh is not None else np.zeros(90))
        hists.append(described.hists)
        rcent.append(described.region_centroids)
        rview += [i] * len(described.hists)
    if not hists:
        raise ValueError("no view of the part could be described; is the mesh in metres?")
    return ViewDatabase(
        key=key,
        T_acam_part=np.stack(T_acam),
        centroids=np.stack(cents),
        crh=np.stack(crhs),
        hists=np.vstack(hists),
        region_view=np.asarray(rview, dtype=np.int64),
        region_centroids=np.vstack(rcent),
        view_dirs=dirs,
    )


def _intrinsics(camera: KinectSettings) -> dict[str, float]:
    return {k: getattr(camera, k) for k in ("width", "height", "fx", "fy", "cx", "cy", "min_range", "max_range")}


def database_key(mesh_hash: str, views: ViewSettings, desc: DescriptorSettings, camera: KinectSettings) -> str:
    """Cache key: mesh hash plus every setting that changes the database content."""
    relevant = {
        "version": DB_VERSION,
        "mesh": mesh_hash,
        "views": views.model_dump(mode="json", exclude={"cache_dir"}),
        "desc": desc.model_dump(mode="json"),
        "camera": camera.model_dump(mode="json") if views.noisy else _intrinsics(camera),
    }
    return hashlib.sha256(json.dumps(relevant, sort_keys=True).encode()).hexdigest()[:20]


def load_or_build(
    mesh: trimesh.Trimesh,
    mesh_hash: str,
    views: ViewSettings,
    desc: DescriptorSettings,
    camera: KinectSettings,
) -> tuple[ViewDatabase, bool]:
    """The cached database of ``mesh`` or a freshly built (and cached) one; ``(db, built_now)``."""
    key = database_key(mesh_hash, views, desc, camera)
    folder = Path(views.cache_dir).expanduser() if views.cache_dir else default_cache_dir()
    path = folder / f"{key}.npz"
    if path.is_file():
        try:
            db = ViewDatabase.load(path)
            if db.key == key:
                return db, False
        except Exception as exc:  # noqa: BLE001 - zip (BadZipFile), EOF, npy and key errors alike: rebuilt, not fatal
            log.warning("view database %s is unreadable (%s: %s); rebuilding it", path, type(exc).__name__, exc)
    db = build_views(mesh, views, desc, camera, key=key)
    try:
        db.save(path)
    except OSError as exc:  # a read-only cache only costs a rebuild next time
        log.warning("cannot cache the view database at %s: %s", path, exc)
    return db, True
