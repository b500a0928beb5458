"""Teaching per markers per part (:mod:`asmteach.plugins.detectors.aruco.marker_count`): kept markers, the bound,
the report."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from asmteach.core import geometry
from asmteach.core.errors import UserError
from asmteach.plugins.detectors.aruco.camera import c615_like
from asmteach.plugins.detectors.aruco.marker_count import (
    generated_task,
    keep_markers,
    precision_bound,
    write_marker_count_report,
)
from asmteach.plugins.detectors.aruco.pnp import MarkerObservation, PartPose, project
from asmteach.plugins.detectors.aruco.scene import DemoFrame
from asmteach.plugins.detectors.aruco.teacher import FrameResult


def test_keep_markers_starts_with_the_pair_a_camera_sees_together(tmp_path: Path) -> None:
    task = generated_task("cap_on_post:1", tmp_path)  # 4 + 4 markers
    assert len(task.part_a.markers) == 4 and len(task.part_b.markers) == 4
    one = keep_markers(task, 1)
    assert len(one.part_a.markers) == 1 and len(one.part_b.markers) == 1
    na = one.part_a.markers[0].T_part_marker[:3, 2]
    nb = (task.T_A_B @ one.part_b.markers[0].T_part_marker)[:3, 2]
    assert float(na @ nb) > 0.0
    three = keep_markers(task, 3)
    assert [m.id for m in three.part_a.markers[:1]] == [one.part_a.markers[0].id]
    assert len({m.id for m in three.part_a.markers}) == 3
    assert len(keep_markers(task, 4).part_b.markers) == 4
    with pytest.raises(UserError, match="family:index"):
        generated_task("no_such_family:0", tmp_path)


def test_precision_bound_shrinks_with_more_frames_and_reports_the_corner_noise() -> None:
    cam = c615_like()
    rng = np.random.default_rng(0)
    h = 0.01
    sq = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])
    T_A_B = geometry.from_rotvec(np.zeros(3), np.array([0.03, 0.0, 0.0]))
    results, truth = [], []
    for k in range(12):
        T_cam_A = geometry.from_rotvec(
            np.radians([180.0 + 2 * np.sin(k), 2 * np.cos(k), 0.0]), np.array([0.0, 0.0, 0.45])
        )
        obs = {}
        for role, T in (("A", T_cam_A), ("B", T_cam_A @ T_A_B)):
            px = project(T, sq, cam.K, cam.dist_array) + rng.normal(0.0, 0.05, (4, 2))
            obs[role] = MarkerObservation(1 if role == "A" else 2, 2 * h, np.eye(4), px)
        pa = PartPose(T_cam_A, 0.05, [1], [0.05])
        pb = PartPose(T_cam_A @ T_A_B, 0.05, [2], [0.05])
        results.append(FrameResult(k, pa, pb, [obs["A"]], [obs["B"]]))
        truth.append(DemoFrame(k, "assembled", T_cam_A, T_cam_A @ T_A_B))
    few = precision_bound(results, truth, [0, 1, 2], T_A_B, cam)
    many = precision_bound(results, truth, list(range(12)), T_A_B, cam)
    assert 0.03 < many["corner_sigma_px"] < 0.07
    assert many["bound_mm"] < few["bound_mm"] and many["bound_deg"] < few["bound_deg"]
    assert many["seen_a"] == 1 and many["seen_b"] == 1


def test_report_counts_markers_seen_and_repeated_trials_once(tmp_path: Path) -> None:
    def row(struct: str, k: int, seen: int, dt: float, seed: int = 7) -> dict:
        return {
            "ok": True,
            "seed": seed,
            "metrics": {
                "structure": struct,
                "markers_a": k,
                "markers_b": k,
                "markers_per_part": k,
                "seen_a": seen,
                "seen_b": seen,
                "dt_mm": dt,
                "drot_deg": dt,
                "bound_mm": 0.1,
                "bound_deg": 0.1,
                "corner_sigma_px": 0.03,
            },
        }

    rows = [
        row("s1", 1, 1, 0.2),
        row("s1", 2, 1, 0.2),
        row("s1", 3, 2, 0.1),
        row("s2", 1, 1, 0.4),
        {"ok": False, "seed": 7, "metrics": None},
    ]
    paths = write_marker_count_report(rows, tmp_path)
    md = paths[0].read_text()
    # Kept: every trial in its own group (s1 k=1 and s2 at 1 marker, s1 k=2, s1 k=3).
    assert "| kept | 1 | 2 | 0.3 |" in md
    assert "| kept | 2 | 1 | 0.2 |" in md
    # Seen: s1 with 2 markers kept saw one, as with 1 kept: the same trial, counted once beside s2.
    assert "| seen | 1 | 2 | 0.3 |" in md
    assert "| seen | 2 | 1 | 0.1 |" in md
    assert "4 trials (3 distinct), 1 failed." in md
