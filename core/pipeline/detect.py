"""The spawn and detect stages: the parts put in random stable rests, then sensed and detected.

Poses in the world frame, metres; errors against the simulator's truth in mm and degrees.
"""

from __future__ import annotations

import numpy as np

from asmteach.core import geometry
from asmteach.core.detect_correct import detect_and_correct
from asmteach.core.failures import FailureCause
from asmteach.core.interfaces import PartModel, Robot
from asmteach.core.models import Detection, TablePlane
from asmteach.core.perception.second_view import DepthView
from asmteach.core.pipeline.active_look import closer_for
from asmteach.core.pipeline.stage import Run, StageFailed
from asmteach.core.pose_error import pose_error
from asmteach.core.scene import random_start_poses

__all__ = ["detect_stage", "not_found_cause", "sense", "sense_views", "spawn_stage", "symmetric_surface_error"]


def symmetric_surface_error(part: PartModel, T_est: np.ndarray, T_true: np.ndarray, n: int = 500) -> float:
    """Mean distance (mm) from the part's surface at ``T_est`` to its surface at ``T_true`` (ADD-S).

    Unlike the raw pose error, it is zero for a pose that differs by one of
    the part's symmetries, which is what matters for grasping it.
    """
    from scipy.spatial import cKDTree

    # Fixed seeds: trimesh samples from fresh OS entropy without one, and the metric changed from run to run.
    a = geometry.transform_points(T_est, np.asarray(part.mesh.sample(n, return_index=False, seed=0), float))
    b = geometry.transform_points(T_true, np.asarray(part.mesh.sample(4000, return_index=False, seed=1), float))
    d, _ = cKDTree(b).query(a)
    return float(1000.0 * d.mean())


def not_found_cause(det: Detection) -> FailureCause:
    """A detection that found no part: ambiguous when it lists rival poses the view cannot tell apart
    (``details["ambiguous"]``, as the cvfh detector marks them), else not found."""
    return FailureCause.DETECT_AMBIGUOUS if det.details.get("ambiguous") else FailureCause.DETECT_NOT_FOUND


def spawn_stage(run: Run, robot: Robot, a: PartModel, b: PartModel, table: TablePlane) -> dict[str, np.ndarray]:
    with run.stage("spawn") as d:
        rng = np.random.default_rng([run.cfg.seed, 11])
        T_a, T_b = random_start_poses([a, b], table.height, run.execution.scene, rng)
        robot.reset_world(table, {a.name: (a, T_a), b.name: (b, T_b)})
        # the simulator's poses are the truth (a part may settle slightly)
        truth = {a.name: robot.part_pose(a.name), b.name: robot.part_pose(b.name)}
        for name, T in truth.items():
            d[name] = geometry.to_xyz_mm_rpy_deg(T)
        return truth


def detect_stage(
    run: Run, robot: Robot, parts: tuple[PartModel, ...], table: TablePlane, truth: dict[str, np.ndarray]
) -> dict[str, Detection]:
    with run.stage("detect", total=len(parts)) as d:
        detector = run.plugin("detector")
        corrector = run.plugin("corrector") if run.cfg.corrector is not None else None
        depth, views = sense_views(robot, run.execution.depth_frames)
        cloud, viewpoint = views[0].cloud, views[0].viewpoint
        np.save(run.out / "depth.npy", depth.astype(np.float32))
        out: dict[str, Detection] = {}
        for part in parts:
            detector.prepare(part)
            # Only A is looked at again once moved (run.py): only A may go on with one of two hull twins.
            again = run.execution.look_again != "never" and part is parts[0]
            det = detect_and_correct(
                detector,
                corrector,
                cloud,
                part,
                table,
                viewpoint=viewpoint,
                provisional=again,
                views=views[1:],
                symmetries=run.symmetries(part) if len(views) > 1 else None,
                # the fixed cameras left it ambiguous: a wrist camera looks closer (parts found so far in the way)
                closer=closer_for(
                    run, robot, part, views, table, d, [(p, out[p.name].best) for p in parts if p.name in out]
                ),
            )
            if not det.found or det.rough is None:
                run.report.detections.append(det)
                raise StageFailed(f"{part.name} not found: {det.reason}", cause=not_found_cause(det))
            if "correction_error" in det.details:
                run.report.detections.append(det)
                raise StageFailed(
                    f"{part.name} found but not corrected: {det.details['correction_error']}",
                    cause=FailureCause.CORRECT,
                )
            T_true = truth[part.name]
            det.details["T_world_part_true"] = T_true.tolist()
            for key in ("rough", "corrected"):
                T = getattr(det, key)
                if T is not None:
                    err = pose_error(T, T_true, (), run.symmetries(part))
                    surface_mm = symmetric_surface_error(part, T, T_true)
                    det.details[f"{key}_error"] = {**err.short(), "surface_mm": surface_mm}
            out[part.name] = det
            run.report.detections.append(det)
            best = det.details.get("corrected_error") or det.details["rough_error"]
            d[part.name] = {k: round(v, 3) for k, v in best.items()}
            run.report.metrics[f"detect_{part.name}_surface_mm"] = best["surface_mm"]
            run.hook("asmteach_stage_progress", stage="detect", advance=1, message=part.name)
        from asmteach.core.run_figures import detection_figure

        path = detection_figure(run.out / "detection.png", depth, cloud, parts, out, truth)
        run.artefact("detection", path, "png")
        return out


def sense(robot: Robot, frames: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """``(depth image, cloud (n, 3) world frame, camera centre or None)`` from the robot's first depth camera.

    The clouds of ``frames`` depth frames are stacked (the parts stand still;
    the sensor's noise is new in every frame, so the detector's voxel filter
    and ICP average it out); the depth image is the first frame's. :func:`sense_views` gives every camera.
    """
    depth, views = sense_views(robot, frames, cameras=1)
    return depth, views[0].cloud, views[0].viewpoint


def _shot(robot: Robot, view: int) -> tuple[np.ndarray, np.ndarray]:
    return robot.sense_depth() if view == 0 else robot.sense_depth(view=view)  # type: ignore[call-arg]


def sense_views(robot: Robot, frames: int = 1, cameras: int | None = None) -> tuple[np.ndarray, list[DepthView]]:
    """``(first camera's depth image, every view)``: one :class:`DepthView` (stacked cloud of ``frames``
    frames, world frame, and camera centre or ``None``) per depth camera of the robot
    (:meth:`~asmteach.core.robot.Robot.depth_views`, or the first ``cameras``)."""
    # asked for one camera, a world need not say how many it has
    n = 1 if cameras == 1 else min(robot.depth_views(), cameras or robot.depth_views())
    depth = np.empty((0, 0))
    views = []
    for view in range(n):
        first, cloud = _shot(robot, view)
        if frames > 1:
            cloud = np.concatenate([cloud] + [_shot(robot, view)[1] for _ in range(frames - 1)])
        try:
            # the first camera is asked as it always was (no view argument): a world with one need not take it
            eye = robot.camera_pose() if view == 0 else robot.camera_pose(view=view)  # type: ignore[call-arg]
            viewpoint = np.asarray(eye)[:3, 3]
        except NotImplementedError:
            viewpoint = None
        if view == 0:
            depth = first
        views.append(DepthView(cloud, viewpoint))
    return depth, views
