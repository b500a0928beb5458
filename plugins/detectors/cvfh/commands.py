"""``asmteach detect MODEL_OR_CONFIG --cloud scene.pcd --out detection.json``.

The part comes from a mesh file (STL/OBJ/PLY/OFF), a scan of it (a PCD/PLY/XYZ
point cloud: only detectors that take cloud models, ``fpfh_ransac`` by
default, and no placement correction), a part YAML, a structure YAML (``--part
a|b``) or a run config (its structure, detector, corrector and table). Every
cloud is read by :func:`asmteach.core.clouds.read_cloud` (PCD in all three
encodings with NaNs and extra fields, PLY, XYZ; units checked, millimetres
converted with a warning). ``detection.json`` holds ``found``, ``reason``,
``rough`` and ``corrected`` (``T_world_part`` 4x4 metres, ``xyz_mm``,
``rpy_deg``), ``fitness``, ``inlier_rmse``, ``timing_ms`` per stage
(``total`` is the detection proper, without start-up, file loading or the
view-database build), and ``frame_source``.

The cloud's frame (``--frame``, default ``auto``): the detectors work in the
world frame (metres, z up, the table below the part). A depth sensor gives its
cloud in its camera frame (x right, y down, z forward); such a cloud is put in
the world with the camera pose of ``--extrinsics FILE`` (``frame_source:
extrinsics``) or, without one, the table plane found in the cloud (the table
top at ``--table-height``, default 0; ``frame_source: table_plane``); a
world-frame cloud is used as it is (``frame_source: world``). ``auto`` takes
the camera frame when ``--extrinsics`` is given or the cloud looks like a
sensor's view (:func:`asmteach.core.clouds.guess_frame`), and says why.
For a camera-frame cloud the camera centre is the camera pose's origin and
``camera_frame`` repeats the poses in the cloud's own frame (``T_cam_part``).

For a world-frame cloud the camera centre (world frame, metres) comes from, in
this order: ``--viewpoint X Y Z``; the cloud file (a PCD's ``VIEWPOINT``
header, the ``comment viewpoint X Y Z`` line of a PLY written by asmteach's
renderer); a run config (the detector's ``viewpoint`` setting, else the
robot's camera mount). With none of them the command stops (exit 2) and says
which to give: there is no default camera.

Exit codes: 0 found, 1 not found (the JSON says why), 2 bad input (one line).
"""

from __future__ import annotations

import argparse
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core import clouds, geometry, registry
from asmteach.core.config import load_run_config
from asmteach.core.detect_correct import detect_and_correct
from asmteach.core.errors import UserError
from asmteach.core.hooks import hookimpl
from asmteach.core.interfaces import Corrector, Detector, PartModel
from asmteach.core.io import check_out_file, read_yaml, write_json
from asmteach.core.models import Detection, TablePlane
from asmteach.core.parts import load_parts
from asmteach.core.perception.viewpoint import NO_VIEWPOINT

__all__ = ["SceneCloud", "asmteach_add_commands", "detection_report", "load_cloud", "place_cloud"]

log = logging.getLogger(__name__)

CLOUD_MODEL_DETECTOR = "fpfh_ransac"
"""The detector used for a part given as a scan when none is named (``cvfh_icp`` renders views of a mesh)."""


@hookimpl
def asmteach_add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register ``asmteach detect``."""
    p = subparsers.add_parser(
        "detect",
        help="rough + corrected pose of a part in a depth cloud (world frame, metres, z up)",
        description=__doc__.split("\n\n")[1] if __doc__ else None,
    )
    p.add_argument(
        "source", metavar="MODEL_OR_CONFIG", help="mesh, scan (PCD/PLY cloud), part YAML, structure YAML or run config"
    )
    p.add_argument("--cloud", required=True, help="point cloud file (PCD/PLY/XYZ), world or camera frame")
    p.add_argument(
        "--frame",
        choices=["auto", "world", "camera"],
        default="auto",
        help="frame of the cloud: world (z up) or a camera's (z forward); auto guesses and says why",
    )
    p.add_argument(
        "--extrinsics",
        default=None,
        metavar="FILE",
        help="camera pose in the world for a camera-frame cloud (YAML/JSON: T_world_cam 4x4, T_cam_world, "
        "rvec/tvec of a board on the table, or translation + rotation); default: the table plane in the cloud",
    )
    p.add_argument(
        "--cloud-units", choices=["auto", "m", "mm"], default="auto", help="cloud units (auto: checked, mm converted)"
    )
    p.add_argument("--out", required=True, help="detection JSON to write")
    p.add_argument("--part", choices=["a", "b"], default="a", help="which part of a structure or run config")
    p.add_argument("--detector", default=None, help="detector plugin (default: the config's, else cvfh_icp)")
    p.add_argument("--corrector", default=None, help="corrector plugin (default: the config's, else stable_placements)")
    p.add_argument("--no-correct", action="store_true", help="skip the placement correction")
    p.add_argument(
        "--viewpoint",
        type=float,
        nargs=3,
        metavar=("X", "Y", "Z"),
        help="camera centre, world frame, metres (default: the cloud file's header, else the config's camera)",
    )
    p.add_argument(
        "--table-height",
        type=float,
        default=None,
        help="known table top z (metres); else fitted (a table-plane frame puts it at this z, default 0)",
    )
    p.add_argument("--units", choices=["m", "mm"], default="m", help="units of a mesh or scan file given directly")
    p.add_argument("--seed", type=int, default=None, help="seed of the detector (default: the config's, else 0)")
    p.set_defaults(func=_cmd_detect)


def _cmd_detect(args: argparse.Namespace) -> int:
    out = check_out_file(args.out)
    part, det_choice, cor_choice, seed, table, config_eye = _load_source(args)
    scan = part.points is not None
    if args.detector:
        det_choice = (args.detector, {})
    elif scan and not registry.get_class("detectors", det_choice[0]).takes_cloud_models:
        log.warning("%s is given as a scan: detecting with %s", part.name, CLOUD_MODEL_DETECTOR)
        det_choice = (CLOUD_MODEL_DETECTOR, {})
    if args.corrector:
        cor_choice = (args.corrector, {})
    if args.no_correct:
        cor_choice = None
    if scan and cor_choice is not None:
        if args.corrector:
            raise UserError(
                f"{part.name} is given as a scan: a corrector needs the part's closed surface (its stable "
                "placements); drop --corrector or give the part's mesh"
            )
        cor_choice = None  # a scan's convex hull has no meaningful stable placements
    detector = registry.create("detectors", det_choice[0], dict(det_choice[1]), seed=seed)
    assert isinstance(detector, Detector)
    if scan and not detector.takes_cloud_models:
        raise UserError(
            f"{det_choice[0]} cannot use a part given as a scan ({args.source}): it needs a mesh; "
            f"use --detector {CLOUD_MODEL_DETECTOR} or give the part's mesh"
        )
    corrector = None
    if cor_choice is not None:
        corrector = registry.create("correctors", cor_choice[0], dict(cor_choice[1]), seed=seed)
        assert isinstance(corrector, Corrector)
    if args.table_height is not None:
        table = TablePlane(height=args.table_height)
    cloud = load_cloud(Path(args.cloud), units=args.cloud_units)
    scene = place_cloud(
        cloud,
        frame=args.frame,
        extrinsics=args.extrinsics,
        viewpoint=args.viewpoint,
        config_eye=config_eye,
        setting=det_choice[1].get("viewpoint"),
        table_height=table.height if table is not None else None,
        seed=seed,
    )
    print(f"cloud frame: {scene.frame_source}: {scene.how}")
    if scene.table is not None:
        table = scene.table

    t0 = time.perf_counter()
    detector.prepare(part)  # the view-database build is not detection time
    prep_ms = 1000.0 * (time.perf_counter() - t0)
    detection = detect_and_correct(detector, corrector, scene.points, part, table, viewpoint=scene.viewpoint)
    report = detection_report(detection)
    report["timing_ms_excluded"] = {"prepare": round(prep_ms, 1)}
    report["detector"] = det_choice[0]
    report["corrector"] = cor_choice[0] if cor_choice else None
    report["model"] = "scan" if scan else "mesh"
    report.update(scene.report(detection))
    write_json(out, report)
    if detection.found:
        pose = report["corrected"] or report["rough"]
        print(
            f"{part.name}: found; xyz {pose['xyz_mm']} mm, rpy {pose['rpy_deg']} deg (world), "
            f"fitness {detection.fitness:.3f}, {detection.timing_ms.get('total', 0):.0f} ms -> {out}"
        )
        return 0
    print(f"{part.name}: not found: {detection.reason} -> {out}")
    return 1


@dataclass
class SceneCloud:
    """The cloud ``asmteach detect`` detects in: world frame points and where the frame came from."""

    points: np.ndarray
    """(n, 3) world frame, metres (NaN rows kept)."""
    viewpoint: np.ndarray
    """(3,) camera centre, world frame, metres."""
    frame_source: Literal["world", "extrinsics", "table_plane"]
    how: str
    """One line: the frame used and why."""
    T_world_cam: np.ndarray | None = None
    """Camera pose in the world (4x4, metres) for a camera-frame cloud."""
    table: TablePlane | None = None
    """The table a table-plane frame puts at the known height (``None``: the detector fits it)."""
    notes: list[str] = field(default_factory=list)

    def report(self, det: Detection) -> dict[str, Any]:
        """The frame fields of ``detection.json``; poses in the camera frame too when the cloud was in one."""
        doc: dict[str, Any] = {"frame_source": self.frame_source, "frame": self.how, "cloud_notes": self.notes}
        if self.T_world_cam is not None:
            doc["T_world_cam"] = self.T_world_cam.tolist()
            T_cam_world = geometry.invert(self.T_world_cam)

            def in_cam(T: np.ndarray | None) -> dict[str, Any] | None:
                if T is None:
                    return None
                T_cam_part = T_cam_world @ np.asarray(T)
                return {"T_cam_part": T_cam_part.tolist(), **geometry.to_xyz_mm_rpy_deg(T_cam_part)}

            doc["camera_frame"] = {"rough": in_cam(det.rough), "corrected": in_cam(det.corrected)}
        return doc


def place_cloud(
    cloud: clouds.Cloud,
    *,
    frame: str = "auto",
    extrinsics: str | Path | None = None,
    viewpoint: list[float] | None = None,
    config_eye: np.ndarray | None = None,
    setting: object = None,
    table_height: float | None = None,
    seed: int = 0,
) -> SceneCloud:
    """Put ``cloud`` in the world frame and find the camera centre (see the module docstring for the rules).

    ``frame`` is ``auto``, ``world`` or ``camera``; ``extrinsics`` a file with the camera pose
    (:func:`asmteach.core.clouds.load_extrinsics`); ``viewpoint`` the ``--viewpoint`` of a world-frame
    cloud; ``config_eye`` and ``setting`` the run config's camera and the detector's ``viewpoint`` setting;
    ``table_height`` the table top z a table-plane frame puts the table at (metres, default 0).
    :class:`UserError` for contradicting options or a camera pose that cannot be found.
    """
    if extrinsics is not None and frame == "world":
        raise UserError("--extrinsics maps a camera-frame cloud into the world; drop it or --frame world")
    why = ""
    if frame == "auto":
        if extrinsics is not None:
            frame, why = "camera", "--extrinsics is given"
        else:
            frame, why = clouds.guess_frame(cloud, seed=seed)
        why = f" (auto: {why})"
    notes = list(cloud.notes)
    if frame == "world":
        eye = choose_viewpoint(viewpoint, cloud, config_eye, setting)
        how = f"the cloud is used as given, in the world frame{why}"
        return SceneCloud(cloud.points, eye, "world", how, notes=notes)
    if viewpoint is not None:
        raise UserError(
            f"--viewpoint is for a world-frame cloud, and this one is in a camera frame{why}: its camera centre is "
            "the camera pose's origin (drop --viewpoint, or give --frame world)"
        )
    ext = clouds.load_extrinsics(extrinsics) if extrinsics is not None else None
    wc = clouds.to_world(cloud, extrinsics=ext, table_height=table_height, seed=seed)
    table = None
    if wc.table is not None:
        table = TablePlane(height=wc.table.table_height)  # the frame was built with the table at that z
    return SceneCloud(wc.points, wc.viewpoint, wc.frame, wc.how + why, wc.T_world_cam, table, notes)  # type: ignore[arg-type]


def choose_viewpoint(
    given: list[float] | None, cloud: clouds.Cloud, config_eye: np.ndarray | None, setting: object = None
) -> np.ndarray:
    """The camera centre ((3,), world frame, metres) of a world-frame cloud: the user's, the file's, the config's.

    ``given`` is ``--viewpoint``; ``cloud`` the cloud as read (its header's viewpoint, see
    :attr:`asmteach.core.clouds.Cloud.viewpoint`); ``config_eye`` the run config's camera; ``setting``
    the detector's own ``viewpoint`` setting from the config, which wins over
    the robot's camera. :class:`UserError` when none gives one.
    """
    if given is not None:
        return np.asarray(given, dtype=float)
    if cloud.viewpoint is not None:
        return cloud.viewpoint
    if setting is not None:
        return np.asarray(setting, dtype=float)
    if config_eye is not None:
        return config_eye
    name = cloud.path.name if cloud.path is not None else "the cloud"
    raise UserError(f"{name}: {NO_VIEWPOINT}")


def detection_report(det: Detection) -> dict[str, Any]:
    """The JSON document of ``asmteach detect`` (poses as 4x4 lists plus xyz mm / rpy deg)."""

    def pose(T: np.ndarray | None, **extra: Any) -> dict[str, Any] | None:
        if T is None:
            return None
        return {"T_world_part": np.asarray(T).tolist(), **geometry.to_xyz_mm_rpy_deg(T), **extra}

    details = {k: v for k, v in det.details.items() if k != "placement_id"}
    return {
        "part": det.part,
        "found": det.found,
        "reason": det.reason,
        "rough": pose(det.rough),
        "corrected": pose(det.corrected, placement_id=det.details.get("placement_id")),
        "fitness": det.fitness,
        "inlier_rmse": det.inlier_rmse,
        "timing_ms": det.timing_ms,
        "details": details,
    }


def load_cloud(path: Path, *, units: str = "auto") -> clouds.Cloud:
    """The ``--cloud`` file through :func:`asmteach.core.clouds.read_cloud`; :class:`UserError` when unreadable."""
    return clouds.read_cloud(path, units=units, kind="scene", what="--cloud")  # type: ignore[arg-type]


def _load_source(
    args: argparse.Namespace,
) -> tuple[PartModel, tuple[str, dict], tuple[str, dict] | None, int, Any, np.ndarray | None]:
    """Part, detector choice, corrector choice, seed, table and camera centre (run config only) from MESH_OR_CONFIG."""
    src = Path(args.source)
    det: tuple[str, dict] = ("cvfh_icp", {})
    cor: tuple[str, dict] | None = ("stable_placements", {})
    seed = 0
    table = None
    eye = None
    if not src.is_file():
        raise UserError(f"{src}: no such file")
    raw = read_yaml(src) if src.suffix.lower() in {".yaml", ".yml"} else None
    if isinstance(raw, dict) and "structure" in raw:
        cfg = load_run_config(src)
        part = load_parts(cfg.path(cfg.structure), select=args.part, scans=True)[0]
        det = (cfg.detector.plugin, cfg.detector.settings)
        cor = (cfg.corrector.plugin, cfg.corrector.settings) if cfg.corrector else None
        seed = cfg.seed
        table = TablePlane(height=cfg.table.height)
        eye = _robot_camera(cfg.robot.plugin, cfg.robot.settings, cfg.table.height)
    elif raw is not None and not isinstance(raw, dict):
        raise UserError(f"{src}: expected a YAML mapping (a part, a structure or a run config)")
    else:
        part = load_parts(src, units=args.units, select=args.part, scans=True)[0]
    if args.seed is not None:
        seed = args.seed
    return part, det, cor, seed, table, eye


def _robot_camera(plugin: str, settings: dict[str, Any], table_height: float) -> np.ndarray | None:
    """Camera centre (world, metres) of a run config's robot: its settings' ``camera.eye``, z above the table top.

    That is how the simulated robots mount their depth camera (``camera_pose``
    looks from ``eye`` lifted by the table height); a robot without such a
    setting gives ``None``.
    """
    try:
        robot_settings = registry.get_class("robots", plugin).Settings.model_validate(settings)
    except (UserError, ValueError):  # load_run_config validated it already; this is only a lookup
        return None
    eye = getattr(getattr(robot_settings, "camera", None), "eye", None)
    if eye is None:
        return None
    return np.asarray(eye, dtype=float) + np.array([0.0, 0.0, table_height])
