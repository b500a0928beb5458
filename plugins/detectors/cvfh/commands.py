"""``asmteach detect MESH_OR_CONFIG --cloud scene.ply --out detection.json``.

The part comes from a mesh file (STL/OBJ/PLY/OFF), a part YAML, a structure
YAML (``--part a|b``) or a run config (its structure, detector, corrector and
table); the cloud (PLY/PCD, read with Open3D) is in the world frame, metres,
z up, the table below the part. ``detection.json`` holds ``found``,
``reason``, ``rough`` and ``corrected`` (``T_world_part`` 4x4 metres,
``xyz_mm``, ``rpy_deg``), ``fitness``, ``inlier_rmse`` and ``timing_ms`` per
stage; ``timing_ms.total`` is the detection proper (detector + corrector),
without start-up, file loading or the view-database build.

The camera centre (world frame, metres; the detector and the corrector need
it) comes from, in this order: ``--viewpoint X Y Z``; the cloud file (a PCD's
``VIEWPOINT`` header, the ``comment viewpoint X Y Z`` line of a PLY written by
asmteach's renderer); a run config (the detector's ``viewpoint`` setting, else
the robot's camera mount). With none of them the command stops (exit 2) and
says which to give: there is no default camera.

Exit codes: 0 found, 1 not found (the JSON says why), 2 bad input (one line).
"""

from __future__ import annotations

import argparse
import inspect
import logging
import time
from pathlib import Path
from typing import Any

import numpy as np

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core import geometry, registry
from asmteach.core.config import load_run_config
from asmteach.core.errors import UserError
from asmteach.core.hooks import hookimpl
from asmteach.core.interfaces import Corrector, Detector, PartModel
from asmteach.core.io import read_yaml, write_json
from asmteach.core.models import Detection, TablePlane
from asmteach.core.parts import load_parts
from asmteach.plugins.detectors.cvfh.detector import NO_VIEWPOINT
from asmteach.plugins.detectors.depth_camera import read_viewpoint

import open3d as o3d  # isort: skip

__all__ = ["asmteach_add_commands", "detection_report", "load_cloud", "run_detection"]

log = logging.getLogger(__name__)



@hookimpl
def asmteach_add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register ``asmteach detect``."""
    p = subparsers.add_parser(
        "detect",
        help="rough + corrected pose of a part in a depth cloud (world frame, metres, z up)",
        description=__doc__.split("\n\n")[1] if __doc__ else None,
    )
    p.add_argument("source", metavar="MESH_OR_CONFIG", help="mesh file, part YAML, structure YAML or run config")
    p.add_argument("--cloud", required=True, help="point cloud file (PLY/PCD), world frame, metres")
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
    p.add_argument("--table-height", type=float, default=None, help="known table top z (metres); else fitted")
    p.add_argument("--units", choices=["m", "mm"], default="m", help="units of a mesh file given directly")
    p.add_argument("--seed", type=int, default=None, help="seed of the detector (default: the config's, else 0)")
    p.set_defaults(func=_cmd_detect)


def _cmd_detect(args: argparse.Namespace) -> int:
    part, det_choice, cor_choice, seed, table, config_eye = _load_source(args)
    if args.detector:
        det_choice = (args.detector, {})
    if args.corrector:
        cor_choice = (args.corrector, {})
    if args.no_correct:
        cor_choice = None
    detector = registry.create("detectors", det_choice[0], dict(det_choice[1]), seed=seed)
    assert isinstance(detector, Detector)
    corrector = None
    if cor_choice is not None:
        corrector = registry.create("correctors", cor_choice[0], dict(cor_choice[1]), seed=seed)
        assert isinstance(corrector, Corrector)
    if args.table_height is not None:
        table = TablePlane(height=args.table_height)
    cloud = load_cloud(Path(args.cloud))
    viewpoint = choose_viewpoint(args.viewpoint, Path(args.cloud), config_eye, det_choice[1].get("viewpoint"))

    t0 = time.perf_counter()
    detector.prepare(part)  # the view-database build is not detection time
    prep_ms = 1000.0 * (time.perf_counter() - t0)
    detection = run_detection(detector, corrector, cloud, part, table, viewpoint=viewpoint)
    report = detection_report(detection)
    report["timing_ms_excluded"] = {"prepare": round(prep_ms, 1)}
    report["detector"] = det_choice[0]
    report["corrector"] = cor_choice[0] if cor_choice else None
    write_json(args.out, report)
    if detection.found:
        pose = report["corrected"] or report["rough"]
        print(
            f"{part.name}: found; xyz {pose['xyz_mm']} mm, rpy {pose['rpy_deg']} deg, "
            f"fitness {detection.fitness:.3f}, {detection.timing_ms.get('total', 0):.0f} ms -> {args.out}"
        )
        return 0
    print(f"{part.name}: not found: {detection.reason} -> {args.out}")
    return 1


def choose_viewpoint(
    given: list[float] | None, cloud: Path, config_eye: np.ndarray | None, setting: object = None
) -> np.ndarray:
    """The camera centre ((3,), world frame, metres) for ``asmteach detect``: the user's, the file's, the config's.

    ``given`` is ``--viewpoint``; ``cloud`` the cloud file (its header, see
    :func:`read_viewpoint`); ``config_eye`` the run config's camera; ``setting``
    the detector's own ``viewpoint`` setting from the config, which wins over
    the robot's camera. :class:`UserError` when none gives one.
    """
    if given is not None:
        return np.asarray(given, dtype=float)
    try:
        from_file = read_viewpoint(cloud)
    except ValueError as exc:
        raise UserError(f"--cloud: {exc}; fix the line or give --viewpoint X Y Z") from None
    if from_file is not None:
        return from_file
    if setting is not None:
        return np.asarray(setting, dtype=float)
    if config_eye is not None:
        return config_eye
    raise UserError(f"{cloud.name}: {NO_VIEWPOINT}")


def run_detection(
    detector: Detector,
    corrector: Corrector | None,
    cloud: np.ndarray,
    part: PartModel,
    table: TablePlane | None = None,
    *,
    viewpoint: np.ndarray | None = None,
) -> Detection:
    """Detect, then correct the rough pose (when a corrector is given); timings include the correction.

    ``viewpoint`` ((3,), world frame, metres) is the camera centre, or ``None``
    for the detector's own setting (a detector without one raises :class:`UserError`).
    The corrector gets the viewpoint the detector used (``details["viewpoint"]``) when its ``correct`` takes one.
    """
    det = detector.detect(cloud, part, table, viewpoint=viewpoint)
    if not det.found or corrector is None or det.rough is None:
        return det
    t0, c0 = time.perf_counter(), time.process_time()
    used_table = table or _table_of(det)
    segment = part_segment(cloud, det.rough, part, used_table)
    try:
        used_eye = det.details.get("viewpoint", viewpoint)
        if used_eye is not None and _takes_viewpoint(corrector):
            corr = corrector.correct(det.rough, part, used_table, segment, viewpoint=np.asarray(used_eye, float))
        else:
            corr = corrector.correct(det.rough, part, used_table, segment)
    except UserError as exc:
        det.details["correction_error"] = str(exc)
        det.timing_ms["detect"] = det.timing_ms.get("total", 0.0)
        det.timing_ms["correct"] = round(1000.0 * (time.perf_counter() - t0), 2)
        return det
    ms = 1000.0 * (time.perf_counter() - t0)
    det.corrected = corr.T_world_part
    # "detect" is the detector alone; "total" adds the correction (both without start-up and the view database).
    det.timing_ms["detect"] = det.timing_ms.get("total", 0.0)
    det.timing_ms["correct"] = round(ms, 2)
    det.timing_ms["total"] = round(det.timing_ms["detect"] + ms, 2)
    det.timing_ms["cpu_correct"] = round(1000.0 * (time.process_time() - c0), 2)
    det.details["placement_id"] = corr.placement_id
    return det


def _takes_viewpoint(corrector: Corrector) -> bool:
    """Whether ``corrector.correct`` accepts a ``viewpoint`` keyword (the core interface does not require one)."""
    return "viewpoint" in inspect.signature(corrector.correct).parameters


def _table_of(det: Detection) -> TablePlane:
    raw = det.details.get("table")
    return TablePlane.model_validate(raw) if raw else TablePlane()


def part_segment(cloud: np.ndarray, T_world_part: np.ndarray, part: PartModel, table: TablePlane) -> np.ndarray:
    """Observed points (world) near the detected part and above the table, for correctors that refine."""
    pts = np.asarray(cloud, dtype=float)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    center = geometry.transform_points(T_world_part, np.asarray(part.mesh.bounds).mean(axis=0)[None])[0]
    radius = 0.5 * float(np.linalg.norm(np.ptp(np.asarray(part.mesh.vertices), axis=0)))
    n = np.asarray(table.normal, dtype=float)
    near = np.linalg.norm(pts - center, axis=1) < radius + 0.005
    above = pts @ n - table.height > 0.003
    return pts[near & above]


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


def load_cloud(path: Path) -> np.ndarray:
    """``(n, 3)`` points of a PLY/PCD/XYZ file (Open3D); :class:`UserError` when unreadable."""
    if not path.is_file():
        raise UserError(f"--cloud: no such file {path}")
    if path.suffix.lower() not in {".ply", ".pcd", ".xyz", ".xyzn", ".pts"}:
        raise UserError(f"--cloud: {path.name} is not a point-cloud file; give a .ply or .pcd")
    pc = o3d.io.read_point_cloud(str(path))
    pts = np.asarray(pc.points, dtype=float)
    if len(pts) == 0:
        # Open3D returns an empty cloud for unreadable files as well as empty ones; the detector says which.
        log.warning("%s holds no points (or is not readable)", path)
    return pts.reshape(-1, 3)


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
        part = load_parts(cfg.path(cfg.structure), select=args.part)[0]
        det = (cfg.detector.plugin, cfg.detector.settings)
        cor = (cfg.corrector.plugin, cfg.corrector.settings) if cfg.corrector else None
        seed = cfg.seed
        table = TablePlane(height=cfg.table.height)
        eye = _robot_camera(cfg.robot.plugin, cfg.robot.settings, cfg.table.height)
    elif raw is not None and not isinstance(raw, dict):
        raise UserError(f"{src}: expected a YAML mapping (a part, a structure or a run config)")
    else:
        part = load_parts(src, units=args.units, select=args.part)[0]
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
