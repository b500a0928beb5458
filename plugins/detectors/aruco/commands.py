"""CLI commands of the teaching phase: ``teach``, ``render-demo`` and ``calibrate``."""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
from pydantic import ValidationError

from asmteach.core import geometry
from asmteach.core.config import RunConfig, format_validation_error, load_run_config, validate_settings
from asmteach.core.errors import UserError
from asmteach.core.hooks import hookimpl
from asmteach.core.io import atomic_path, check_out_file, run_folder, write_json, write_model
from asmteach.core.models import AssemblyTask, CameraIntrinsics
from asmteach.core.parts import build_part, load_structure

__all__ = ["asmteach_add_commands", "check_demonstration", "demo_settings", "resolve_camera", "write_demo"]


def demo_settings(cfg: RunConfig):
    """The config's ``demo`` section validated by :class:`~.scene.DemoSettings` (errors name ``demo.<key>``)."""
    return _demo_model(cfg.demo)


def _demo_model(demo: dict):
    from asmteach.plugins.detectors.aruco.scene import DemoSettings

    try:
        return DemoSettings.model_validate(demo)
    except ValidationError as exc:
        raise UserError(format_validation_error(exc, "demo")) from None


def check_demonstration(task: AssemblyTask, demo: dict, camera_file: Path | None):
    """Everything a rendered demonstration of ``task`` needs, checked before any rendering.

    The ``demo`` section (:class:`~.scene.DemoSettings`), the camera (the
    file's intrinsics, or the C615-like default; the renderer draws an ideal
    pinhole camera, so no distortion), and the markers (each part needs one,
    dictionaries known, ids within them and not shared). Returns the demo
    settings; :class:`UserError` in one line otherwise.
    """
    from asmteach.plugins.detectors.aruco.camera import c615_like, load_camera
    from asmteach.plugins.detectors.aruco.markers import marker_bits, marker_table

    settings = _demo_model(demo)
    camera = load_camera(camera_file) if camera_file is not None else c615_like()
    if any(abs(d) > 0 for d in camera.dist):
        raise UserError(
            f"camera {camera_file}: the demonstration renderer draws an ideal pinhole camera; give "
            "intrinsics without distortion (distortion_coefficients all 0)"
        )
    marker_table(task.part_a, task.part_b)  # a part without markers, a shared id, an unknown dictionary
    for part in (task.part_a, task.part_b):
        for m in part.markers:
            marker_bits(m)  # the id exists in its dictionary
    return settings


def resolve_camera(explicit: str | None, cfg: RunConfig | None, frames: Path | None) -> tuple[CameraIntrinsics, str]:
    """Intrinsics from ``--camera``, else the config's ``camera``, else ``camera.yaml`` next to the frames,
    else the C615-like default; returns the camera and where it came from."""
    from asmteach.plugins.detectors.aruco.camera import c615_like

    if explicit:
        return _camera_noting_distortion(explicit), explicit
    if cfg is not None and cfg.camera:
        p = cfg.path(cfg.camera)
        return _camera_noting_distortion(p), str(p)
    if frames is not None:
        folder = frames if frames.is_dir() else frames.parent
        if (folder / "camera.yaml").is_file():
            return _camera_noting_distortion(folder / "camera.yaml"), str(folder / "camera.yaml")
    return c615_like(), "default C615-like intrinsics"


def _camera_noting_distortion(path: str | Path) -> CameraIntrinsics:
    """:func:`~.camera.load_camera`, with a warning when the file gives no distortion (taken as none): a real
    webcam's lens distortion left out shifts marker corners by pixels at the image edges."""
    import logging

    from asmteach.core.io import read_yaml
    from asmteach.plugins.detectors.aruco.camera import load_camera

    camera = load_camera(path)
    try:
        raw = read_yaml(path)
    except UserError:
        raw = None  # an OpenCV FileStorage file: load_camera read it
    if isinstance(raw, dict) and "distortion_coefficients" not in raw:
        logging.getLogger("asmteach").warning(
            "%s gives no distortion_coefficients: the camera is taken as distortion-free; calibrate it "
            "(asmteach calibrate) or write zeros to say so",
            path,
        )
    return camera


def _load_cfg(path: str) -> RunConfig:
    # Only the teaching phase is needed here: other roles' plugins need not be installed.
    cfg = load_run_config(path, check_plugins=False)
    structure = cfg.path(cfg.structure)
    if not structure.is_file():
        raise UserError(f"{path}: structure: no such file {structure}")
    return cfg


def _cmd_teach(args: argparse.Namespace) -> int:
    from asmteach.core import registry
    from asmteach.plugins.detectors.aruco.frames import load_frames

    check_out_file(args.out, example="task.json")  # before any work
    cfg = _load_cfg(args.config)
    task = load_structure(cfg.path(cfg.structure))
    cls = registry.get_class("teachers", cfg.teacher.plugin)
    settings = validate_settings(cls, cfg.teacher.settings, where="teacher.settings")
    frames_path = Path(args.frames)
    camera, cam_source = resolve_camera(args.camera, cfg, frames_path)
    _check_jpegs_whole(frames_path)
    frames = load_frames(frames_path)
    teacher = cls(settings, seed=cfg.seed)
    learned = teacher.teach(frames, camera, task)
    write_model(args.out, learned)
    ev = learned.evidence
    pose = geometry.to_xyz_mm_rpy_deg(learned.T_A_B)
    print(f"taught {learned.name} from {len(frames)} frame(s) ({cam_source})")
    print(f"  T_A_B: xyz {pose['xyz_mm']} mm, rpy {pose['rpy_deg']} deg")
    print(f"  v_a: {np.round(learned.v_a, 4).tolist()} ({ev.insertion_source if ev else '?'})")
    if ev is not None:
        print(
            f"  frames used {len(ev.frames_used)}/{ev.frames_total}, spread {ev.spread_mm:.3f} mm "
            f"{ev.spread_deg:.3f} deg"
        )
    print(f"  wrote {args.out}")
    return 0


def _check_jpegs_whole(folder: Path) -> None:
    """:class:`UserError` for a JPEG frame cut short (no end-of-image marker): OpenCV decodes it with a grey
    bottom and says nothing, and its markers there would be wrong."""
    if not folder.is_dir():
        return
    for f in sorted(folder.iterdir()):
        if f.suffix.lower() not in (".jpg", ".jpeg") or not f.is_file():
            continue
        with open(f, "rb") as fh:
            size = fh.seek(0, 2)
            fh.seek(max(0, size - 64))
            tail = fh.read()
        if size > 2 and b"\xff\xd9" not in tail:  # EOI; a few padding bytes after it are allowed
            raise UserError(
                f"{f}: the JPEG is cut short (no end-of-image marker; {size} bytes); copy it again or "
                "remove it from the frames"
            )


def write_demo(cfg: RunConfig, out: Path, *, camera: CameraIntrinsics | None = None) -> dict:
    """Render the demonstration of ``cfg`` into ``out``: frames, ``camera.yaml``, ``ground_truth.json``."""
    from asmteach.plugins.detectors.aruco.camera import save_camera
    from asmteach.plugins.detectors.aruco.scene import render_demo_frames

    task = load_structure(cfg.path(cfg.structure))
    settings = check_demonstration(task, cfg.demo, cfg.path(cfg.camera) if cfg.camera and camera is None else None)
    if camera is None:
        camera, _ = resolve_camera(None, cfg, None)
    if any(abs(d) > 0 for d in camera.dist):
        raise UserError("render-demo draws an ideal pinhole camera; give a camera file with zero distortion")
    a, b = build_part(task.part_a), build_part(task.part_b)
    out.mkdir(parents=True, exist_ok=True)
    records = []
    for fr, img, visible in render_demo_frames(a, b, task, camera, settings, seed=cfg.seed):
        name = f"frame_{fr.index:04d}.{settings.image_format}"
        with atomic_path(out / name) as tmp:
            if not cv2.imwrite(str(tmp), img):
                raise UserError(f"{out / name}: cannot write the image")
        records.append(
            {
                "file": name,
                "phase": fr.phase,
                "T_cam_A": fr.T_cam_A.tolist(),
                "T_cam_B": fr.T_cam_B.tolist(),
                "visible_markers": visible,
            }
        )
    save_camera(out / "camera.yaml", camera, name="render-demo")
    truth = {
        "structure": task.name,
        "seed": cfg.seed,
        "demo": settings.model_dump(mode="json"),
        "T_A_B": task.T_A_B.tolist(),
        "v_a": np.asarray(task.v_a).tolist(),
        "frames": records,
    }
    write_json(out / "ground_truth.json", truth)
    return truth


def _cmd_render_demo(args: argparse.Namespace) -> int:
    cfg = _load_cfg(args.config)
    task = load_structure(cfg.path(cfg.structure))
    check_demonstration(task, cfg.demo, cfg.path(cfg.camera) if cfg.camera else None)  # before any work
    # Frames of an earlier demonstration never mix with these: the folder is replaced whole at the end
    # (another structure's demonstration is kept unless --force).
    with run_folder(args.out, task.name, force=args.force, marker="ground_truth.json", key=("structure",)) as stage:
        truth = write_demo(cfg, stage)
    n_app = sum(r["phase"] == "approach" for r in truth["frames"])
    print(f"rendered {len(truth['frames'])} frame(s) of {truth['structure']} ({n_app} approach) into {args.out}")
    return 0


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from asmteach.plugins.detectors.aruco.calibrate import (
        BoardSpec,
        ChessboardSpec,
        calibrate_charuco,
        calibrate_chessboard,
        draw_coverage,
    )
    from asmteach.plugins.detectors.aruco.camera import save_camera
    from asmteach.plugins.detectors.aruco.frames import load_named_frames

    check_out_file(args.out, example="camera.yaml")
    if args.coverage:
        check_out_file(args.coverage, flag="--coverage", example="coverage.png")
    board = args.board.lower()
    try:
        if board == "chessboard":
            if args.cols is None or args.rows is None:
                raise UserError("--board chessboard needs --cols and --rows (inner corners, e.g. --cols 9 --rows 6)")
            chess = ChessboardSpec(cols=args.cols, rows=args.rows, square=args.square)
        else:
            if args.cols is not None or args.rows is not None:
                raise UserError("--cols/--rows are for --board chessboard; a ChArUco board is --board NxM squares")
            sx, sy = (int(v) for v in board.split("x"))
            spec = BoardSpec(
                squares_x=sx, squares_y=sy, square=args.square, marker=args.marker, dictionary=args.dictionary
            )
    except ValueError as exc:
        msg = (
            format_validation_error(exc)
            if isinstance(exc, ValidationError)
            else "give --board as NxM ChArUco squares (e.g. 7x5) or chessboard"
        )
        raise UserError(f"--board/--cols/--rows/--square/--marker: {msg}") from None
    _check_jpegs_whole(Path(args.images))
    named = load_named_frames(args.images)
    names, images = [n for n, _ in named], [img for _, img in named]
    if board == "chessboard":
        res = calibrate_chessboard(images, chess, names=names, model=args.model, fix_aspect=args.fix_aspect)
        kind = "chessboard"
    else:
        res = calibrate_charuco(images, spec, names=names, model=args.model, fix_aspect=args.fix_aspect)
        kind = "charuco"
    for name in res.skipped:
        print(f"{name}: board not found, skipped")
    save_camera(
        args.out,
        res.camera,
        name=f"{kind}-calibration",
        notes=f"RMS {res.rms_px:.3f} px over {res.images_used}/{res.images_total} images; {res.model}",
    )
    K = res.camera.K
    print(f"calibrated from {res.images_used}/{res.images_total} image(s): RMS {res.rms_px:.3f} px")
    print(f"  model: {res.model}")
    print(
        f"  fx {K[0, 0]:.2f} fy {K[1, 1]:.2f} cx {K[0, 2]:.2f} cy {K[1, 2]:.2f}; dist "
        f"{np.round(res.camera.dist, 4).tolist()}"
    )
    print("  per-view RMS (px): " + ", ".join(f"{n} {e:.3f}" for n, e in zip(res.used, res.per_view_px, strict=True)))
    coverage = Path(args.coverage) if args.coverage else Path(args.out).with_name(Path(args.out).stem + "_coverage.png")
    canvas, frac = draw_coverage(res)
    with atomic_path(coverage) as tmp:
        if not cv2.imwrite(str(tmp), canvas):
            raise UserError(f"{coverage}: cannot write the coverage picture (give a .png path)")
    print(f"  corner coverage: {frac:.0%} of an 8x6 grid over the image; picture {coverage}")
    print(f"  wrote {args.out}")
    return 0


@hookimpl
def asmteach_add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Add ``teach``, ``render-demo`` and ``calibrate``."""
    p = subparsers.add_parser("teach", help="learn T_A_B and v_a from demonstration frames (folder or video)")
    p.add_argument("config", help="run config (structure, camera, teacher)")
    p.add_argument("--frames", required=True, help="folder of images or a video file")
    p.add_argument("--out", required=True, help="assembly task JSON to write")
    p.add_argument("--camera", default=None, help="camera intrinsics YAML (default: config, then frames folder)")
    p.set_defaults(func=_cmd_teach)

    p = subparsers.add_parser("render-demo", help="render a synthetic demonstration with exact ground truth")
    p.add_argument("config", help="run config (structure, camera, demo section)")
    p.add_argument("--out", required=True, help="output folder for frames, camera.yaml, ground_truth.json")
    p.add_argument("--force", action="store_true", help="replace another structure's demonstration in --out")
    p.set_defaults(func=_cmd_render_demo)

    p = subparsers.add_parser("calibrate", help="camera intrinsics from ChArUco or chessboard photos")
    p.add_argument("--images", required=True, help="folder of board images (or a video)")
    p.add_argument("--out", required=True, help="camera YAML to write")
    p.add_argument(
        "--board",
        default="7x5",
        help="ChArUco squares along x and y (e.g. 7x5), or 'chessboard' (then give --cols and --rows)",
    )
    p.add_argument("--cols", type=int, default=None, help="chessboard inner corners along x, e.g. 9")
    p.add_argument("--rows", type=int, default=None, help="chessboard inner corners along y, e.g. 6")
    p.add_argument("--square", type=float, default=0.04, help="square side, metres")
    p.add_argument("--marker", type=float, default=0.03, help="ChArUco marker side, metres")
    p.add_argument("--dictionary", default="DICT_5X5_100", help="ArUco dictionary of a ChArUco board")
    p.add_argument(
        "--model",
        default="k1k2p1p2k3",
        choices=["k1k2p1p2k3", "k1k2p1p2"],
        help="distortion coefficients estimated (k1k2p1p2 holds k3 at 0)",
    )
    p.add_argument(
        "--fix-aspect",
        action="store_true",
        help="estimate one focal length, fx = fy (OpenCV's CALIB_FIX_ASPECT_RATIO with aspect 1)",
    )
    p.add_argument(
        "--coverage",
        default=None,
        help="PNG of all views' corners over the image (default: <out stem>_coverage.png beside --out)",
    )
    p.set_defaults(func=_cmd_calibrate)
