"""The teach stage: the teacher watches a demonstration and learns T_A_B and v_a (errors in mm, deg)."""

from __future__ import annotations

import numpy as np

from asmteach.core.io import write_model
from asmteach.core.models import AssemblyTask
from asmteach.core.pipeline.stage import Run
from asmteach.core.pose_error import pose_error

__all__ = ["teach_stage"]


def teach_stage(run: Run, true_task: AssemblyTask) -> AssemblyTask:
    with run.stage("teach") as d:
        teacher = run.plugin("teacher")
        camera_file = run.cfg.path(run.cfg.camera) if run.cfg.camera else None
        frames, camera = teacher.demonstrate(true_task, run.cfg.demo, camera_file, run.out / "demonstration")
        d["frames"] = len(frames)
        learned = teacher.teach(frames, camera, true_task)
        err = pose_error(learned.T_A_B, true_task.T_A_B)
        v_true = np.asarray(true_task.v_a, float)
        v_err = float(np.degrees(np.arccos(np.clip(np.dot(learned.v_a, v_true) / np.linalg.norm(v_true), -1, 1))))
        d.update(
            T_A_B_error_mm=round(err.position_mm, 4),
            T_A_B_error_deg=round(err.angle_deg, 4),
            v_a_error_deg=round(v_err, 4),
        )
        run.report.task = learned
        run.report.metrics.update(teach_position_mm=err.position_mm, teach_angle_deg=err.angle_deg, teach_v_a_deg=v_err)
        write_model(run.out / "task.json", learned)
        run.artefact("task", run.out / "task.json", "json")
        return learned
