"""``detection_precision``: the paper's execution-phase detection figure, plus random scenes.

Each trial renders one synthetic scene (:mod:`.scenes`): a library part at one
of its stable placements on the table, seen by the virtual Kinect, detects it
with the chosen detector, corrects the pose with the chosen corrector and
compares both with the ground truth. The trial's ``seed`` picks the scene:

* seeds ``0 .. 4 P - 1`` (``P`` = number of listed placements) are the paper's
  grid: placement ``seed // 4`` in table quarter ``seed % 4``;
* higher seeds are random scenes: part and placement, yaw and position drawn
  from the seed.

Errors are symmetry-aware: the truth is replaced by its equivalent under the
placement's symmetry yaws (about the vertical axis through the centre of mass)
nearest to the estimate. Position errors are of the part-frame origin, in
millimetres, world axes; rotation errors are the world-frame roll, pitch, yaw
of ``R_est R_true^T`` in degrees, plus the geodesic angle.

``summarize`` writes ``detection_precision.md`` and ``detection_precision_cells.csv``
(:mod:`~asmteach.plugins.detectors.cvfh.precision_report`).
"""

from __future__ import annotations

import math
import time
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field

from asmteach.core import geometry, registry
from asmteach.core.config import TableSettings, check_plugin_settings
from asmteach.core.detect_correct import detect_and_correct
from asmteach.core.interfaces import Corrector, Detector, PartModel
from asmteach.core.models import Placement, StrictModel, TablePlane
from asmteach.core.parts import build_part, load_structure
from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings
from asmteach.core.pose_error import pose_error
from asmteach.core.sweep import Experiment
from asmteach.core.symmetry import part_symmetries
from asmteach.plugins.detectors.cvfh.precision_report import write_precision_report
from asmteach.plugins.detectors.cvfh.scenes import QUARTERS, default_camera_pose, place_on_table, render_table_scene

__all__ = ["DetectionPrecision", "part_symmetries", "pose_errors"]


class PartChoice(StrictModel):
    """A library part and the placements (ids of its stable placements) used in the grid."""

    structure: str = Field(description="structure YAML, relative to the experiment file")
    part: Literal["a", "b"] = "a"
    placements: list[int] = Field(min_length=1, description="placement ids (compute_placements order)")


class DetectionParams(StrictModel):
    """Parameters of one detection trial."""

    detector: str = Field("cvfh_icp", description="detector plugin")
    detector_settings: dict[str, Any] = Field(default_factory=dict)
    corrector: str | None = Field("stable_placements", description="corrector plugin; null: none")
    corrector_settings: dict[str, Any] = Field(default_factory=dict)
    parts: list[PartChoice] = Field(min_length=1)
    camera: KinectSettings = Field(default_factory=KinectSettings)
    table: TableSettings = Field(default_factory=TableSettings)
    give_table: bool = Field(False, description="pass the true table plane to the detector (else it is fitted)")
    area: tuple[float, float] = Field((0.24, 0.34), description="random scenes: work-area extent along x, y (m)")
    cells: bool = Field(True, description="seeds below 4 x placements are the paper's quarter grid")
    success_mm: float = Field(5.0, gt=0.0)
    success_deg: float = Field(5.0, gt=0.0)


@lru_cache(maxsize=16)
def _load_part(path: str, which: str) -> PartModel:
    task = load_structure(path)
    return build_part(task.part_a if which == "a" else task.part_b, Path(path).parent)


@lru_cache(maxsize=16)
def _placements(path: str, which: str) -> tuple[Placement, ...]:
    from asmteach.core.rests.placements import compute_placements

    return tuple(compute_placements(_load_part(path, which)))


@lru_cache(maxsize=16)
def _symmetries(path: str, which: str) -> list[np.ndarray]:
    part = _load_part(path, which)
    return part_symmetries(part.mesh, np.asarray(part.center_of_mass, dtype=float))


def pose_errors(
    T_est: np.ndarray,
    T_true: np.ndarray,
    symmetry_yaws: list[float],
    com_part: np.ndarray,
    part_symmetry: list[np.ndarray] | None = None,
) -> dict[str, float]:
    """Signed errors of ``T_est`` against the nearest symmetric equivalent of ``T_true``, as the experiment's columns.

    Equivalents (:func:`asmteach.core.pose_error.pose_error`, nearest by mm + deg): the placement's symmetry
    yaws (about the vertical through the centre of mass) and the part's own symmetry rotations
    (:func:`part_symmetries`). Returns ``x, y, z`` (mm, world axes, part origin), ``roll, pitch, yaw``
    (deg, rpy of ``R_est R_true^T``), ``pos`` (mm) and ``rot`` (deg, geodesic).
    """
    c = geometry.transform_points(T_true, com_part[None])[0]
    # A turn about the vertical through the centre of mass, in the world frame: a left symmetry of T_true.
    turns = [
        geometry.from_rotation(np.eye(3), c) @ geometry.rot_z(-yaw) @ geometry.from_rotation(np.eye(3), -c)
        for yaw in symmetry_yaws or [0.0]
    ]
    err = pose_error(T_est, T_true, left=turns, right=[np.eye(4), *(part_symmetry or [])])
    (x, y, z), (roll, pitch, yaw) = err.dxyz_mm, err.drpy_deg
    return {
        "x": x,
        "y": y,
        "z": z,
        "roll": roll,
        "pitch": pitch,
        "yaw": yaw,
        "pos": err.position_mm,
        "rot": err.angle_deg,
    }


class DetectionPrecision(Experiment):
    """Rough and corrected detection errors on synthetic Kinect scenes (see the module docstring)."""

    Params = DetectionParams

    def check(self, params: DetectionParams) -> None:
        """The detector's and corrector's settings by their plugins' models, before any trial."""
        check_plugin_settings(
            "detectors",
            params.detector,
            params.detector_settings,
            name_key="params.detector",
            settings_key="params.detector_settings",
        )
        if params.corrector is not None:
            check_plugin_settings(
                "correctors",
                params.corrector,
                params.corrector_settings,
                name_key="params.corrector",
                settings_key="params.corrector_settings",
            )

    def _pairs(self, params: DetectionParams) -> list[tuple[str, str, int]]:
        return [(str(self.path(pc.structure)), pc.part, pid) for pc in params.parts for pid in pc.placements]

    def run_trial(self, params: DetectionParams, seed: int, workdir: Path) -> dict[str, Any]:
        pairs = self._pairs(params)
        n_cells = 4 * len(pairs)
        rng = np.random.default_rng([seed, 7])
        quarter = None
        if params.cells and seed < n_cells:
            kind = "cell"
            path, which, pid = pairs[seed // 4]
            quarter = list(QUARTERS)[seed % 4]
            xy = QUARTERS[quarter]
        else:
            kind = "random"
            path, which, pid = pairs[int(rng.integers(len(pairs)))]
            half = np.asarray(params.area) / 2.0
            xy = np.array([0.45, 0.0]) + rng.uniform(-half, half)
        yaw = float(rng.uniform(-np.pi, np.pi))
        part = _load_part(path, which)
        placements = {p.id: p for p in _placements(path, which)}
        if pid not in placements:
            raise ValueError(f"{part.name} has no placement {pid} (it has {sorted(placements)})")
        placement = placements[pid]
        T_true = place_on_table(part.mesh, placement.T_table_part, yaw, xy, params.table.height)

        T_world_cam = default_camera_pose(params.table)
        scene = render_table_scene(
            DepthCamera(params.camera, seed=seed), part.mesh, T_true, table=params.table, T_world_cam=T_world_cam
        )
        detector = registry.create("detectors", params.detector, params.detector_settings, seed=seed)
        corrector = None
        if params.corrector:
            corrector = registry.create("correctors", params.corrector, params.corrector_settings, seed=seed)
        assert isinstance(detector, Detector)
        t0 = time.perf_counter()
        detector.prepare(part)  # view database / features: built once, not detection time
        if corrector is not None and hasattr(corrector, "placements_for"):
            corrector.placements_for(part)  # placements are precomputed per part, like the views
        prepare_ms = 1000.0 * (time.perf_counter() - t0)
        assert corrector is None or isinstance(corrector, Corrector)
        table = TablePlane(height=params.table.height) if params.give_table else None
        # The experiment knows its camera: its centre is the viewpoint of the detector and the corrector.
        det = detect_and_correct(detector, corrector, scene.cloud, part, table, viewpoint=T_world_cam[:3, 3])

        row: dict[str, Any] = {
            "kind": kind,
            "detector": params.detector,
            "part": part.name,
            "placement": pid,
            "cell": f"{part.name}#{pid}",
            "quarter": quarter or "",
            "x_mm": round(float(T_true[0, 3]) * 1000, 1),
            "y_mm": round(float(T_true[1, 3]) * 1000, 1),
            "yaw_deg": round(math.degrees(yaw), 2),
            "cloud_points": len(scene.cloud),
            "part_points": int((scene.frame.labels == 1).sum()),
            "found": det.found,
            "reason": det.reason or "",
            "fitness": det.fitness,
            "prepare_ms": round(prepare_ms, 1),
        }
        for stage, ms in det.timing_ms.items():
            row[f"t_{stage}"] = ms
        for label, T in (("rough", det.rough), ("corr", det.corrected)):
            if T is None:
                continue
            errs = pose_errors(T, T_true, placement.symmetry_yaws, part.center_of_mass, _symmetries(path, which))
            row.update({f"{label}_{k}": round(v, 4) for k, v in errs.items()})
        final = "corr" if det.corrected is not None else "rough"
        row["success"] = bool(
            det.found
            and row.get(f"{final}_pos", math.inf) <= params.success_mm
            and row.get(f"{final}_rot", math.inf) <= params.success_deg
        )
        return row

    # ------------------------------------------------------------ summary
    def summarize(self, rows: list[dict[str, Any]], out_dir: Path) -> list[Path]:
        """The report of :mod:`~asmteach.plugins.detectors.cvfh.precision_report` (markdown and cell CSV)."""
        return write_precision_report(rows, out_dir)
