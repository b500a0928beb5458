"""The whole pipeline in simulation: teach, spawn, sense, detect, correct, grasp, plan, execute, measure.

Every stage calls the configured plugin through its role interface only;
hooks announce each stage (progress bars, reporters). A stage that fails ends
the run as a *result*: ``report.json`` records the stage and the reason, and
everything written so far stays valid (all writes are atomic).

Frames and units: world frame z up, metres and radians inside; reports in mm
and degrees. ``T_A_B`` is B's pose in A's frame; errors of the achieved
assembly are measured in A's frame from the simulator's poses.
"""

from __future__ import annotations

import itertools
import time
import traceback
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from asmteach.core import geometry, registry
from asmteach.core.config import ROLE_OF_KEY, ExecutionSettings, RunConfig, validate_settings
from asmteach.core.detect_correct import detect_and_correct
from asmteach.core.errors import UserError
from asmteach.core.interfaces import AssemblyProblem, PartModel, Robot
from asmteach.core.io import describe_os_error, to_jsonable, write_json, write_model
from asmteach.core.models import AssemblyTask, Detection, Plan, RunReport, StageOutcome, TablePlane
from asmteach.core.pose_error import nearest_symmetric, pose_error
from asmteach.core.robot import World
from asmteach.core.scene import random_start_poses
from asmteach.core.symmetry import part_symmetries

__all__ = ["StageFailed", "run_pipeline"]


class StageFailed(Exception):
    """A stage could not produce its result; the run ends as a recorded failure."""

    def __init__(self, reason: str, details: dict[str, Any] | None = None) -> None:
        super().__init__(reason)
        self.reason = reason
        self.details = details or {}


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


class _Run:
    """State of one run: config, plugins, outputs, hooks."""

    def __init__(self, cfg: RunConfig, out_dir: Path, pm: Any | None) -> None:
        self.cfg, self.out, self.pm = cfg, Path(out_dir), pm
        self.report = RunReport(config=cfg.model_dump(mode="json"), seed=cfg.seed)
        self._symmetries: dict[str, list[np.ndarray]] = {}
        self.execution: ExecutionSettings = cfg.execution

    def symmetries(self, part: PartModel) -> list[np.ndarray]:
        """The part's symmetry transforms (part frame), computed once per run."""
        if part.name not in self._symmetries:
            self._symmetries[part.name] = part_symmetries(part.mesh, np.asarray(part.center_of_mass, float))
        return self._symmetries[part.name]

    def plugin(self, key: str) -> Any:
        choice = getattr(self.cfg, key)
        cls = registry.get_class(ROLE_OF_KEY[key], choice.plugin)
        return cls(validate_settings(cls, choice.settings, where=f"{key}.settings"), seed=self.cfg.seed)

    def hook(self, name: str, **kwargs: Any) -> Any:
        if self.pm is None:
            return None
        return getattr(self.pm.hook, name)(**kwargs)

    def progress(self, stage: str) -> Callable[[str], None]:
        return lambda msg: self.hook("asmteach_stage_progress", stage=stage, advance=0, message=msg)

    def artefact(self, name: str, path: Path, kind: str) -> None:
        self.report.artefacts[name] = str(Path(path).relative_to(self.out)) if Path(path).is_relative_to(
            self.out) else str(path)
        self.hook("asmteach_artefact_written", path=Path(path), kind=kind)

    @contextmanager
    def stage(self, name: str, total: int | None = None) -> Iterator[dict[str, Any]]:
        details: dict[str, Any] = {}
        self.hook("asmteach_stage_started", stage=name, total=total,
                  context={"out_dir": str(self.out), "seed": self.cfg.seed, "config": self.cfg.name})
        t0 = time.perf_counter()
        try:
            yield details
        except Exception as exc:  # noqa: BLE001 - any failure of a stage ends the run as a recorded result
            seconds = time.perf_counter() - t0
            if isinstance(exc, StageFailed):
                reason = exc.reason
                details.update(exc.details)
            elif isinstance(exc, UserError | NotImplementedError):  # bad input; a plugin without an optional method
                reason = str(exc)
            elif isinstance(exc, OSError):  # the file system failed (a full disk): the task failed, no bug
                reason = describe_os_error(exc)
            else:  # a bug or an unforeseen input: the report still says where and why, with the traceback
                reason = f"internal error ({type(exc).__name__}: {exc})"
                details["traceback"] = traceback.format_exc(limit=12)
            self.report.stages.append(StageOutcome(stage=name, ok=False, seconds=round(seconds, 3), reason=reason,
                                                   details=to_jsonable(details)))
            self.report.failed_stage, self.report.reason = name, reason
            self.hook("asmteach_stage_finished", stage=name, ok=False, seconds=seconds, summary={"reason": reason})
            raise StageFailed(reason) from None
        seconds = time.perf_counter() - t0
        self.report.stages.append(StageOutcome(stage=name, ok=True, seconds=round(seconds, 3),
                                               details=to_jsonable(details)))
        self.hook("asmteach_stage_finished", stage=name, ok=True, seconds=seconds,
                  summary={k: v for k, v in details.items() if isinstance(v, (int, float, str))})


def run_pipeline(cfg: RunConfig, out_dir: Path, *, pm: Any | None = None) -> RunReport:
    """Run the whole pipeline of ``cfg`` into ``out_dir``; the report is returned and written.

    Raises :class:`UserError` only for bad input found before anything runs
    (config, structure file); every later failure is recorded in the report.
    """
    from asmteach.core.run_setup import prepare_run

    setup = prepare_run(cfg)  # every object of the run built and checked before anything is written
    cfg = setup.cfg  # the robot's settings now carry the config's table
    if not issubclass(registry.get_class("robots", cfg.robot.plugin), World):
        raise UserError(f"robot.plugin: {cfg.robot.plugin!r} plans but has no world to run in (a robot the run "
                        "executes on is also an asmteach.core.robot.World: reset, execute, grip, sense)")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    run = _Run(cfg, out, pm)
    true_task = setup.task
    part_a, part_b = setup.part_a, setup.part_b
    robot: Robot | None = None
    try:
        learned = _teach(run, true_task)
        robot = run.plugin("robot")
        table = setup.table  # the one table plane of the run (cfg.table.height)
        truth = _spawn(run, robot, part_a, part_b, table)
        detections = _detect(run, robot, (part_a, part_b), table, truth)
        grasps = _grasps(run, robot, part_a, part_b)
        result = _plan(run, robot, learned, part_a, part_b, detections, grasps, table)
        plan, frames = result.plan, []
        head = list(itertools.takewhile(lambda seg: seg.part == part_a.name, plan.segments))
        look = run.execution.look_again
        if head and (look == "always" or (look == "ambiguous" and detections[part_a.name].details.get("ambiguous"))):
            frames += _execute(run, robot, Plan(segments=head), stage="execute_a")
            result, plan = _look_again(run, robot, learned, (part_a, part_b), detections, grasps, table, result,
                                       Plan(segments=plan.segments[len(head):], stats=plan.stats))
        frames += _execute(run, robot, plan)
        if frames:
            _write_animation(run, frames)
        _measure(run, robot, learned, true_task, part_a, part_b, result)
    except StageFailed:
        pass
    finally:
        if robot is not None:
            robot.close()
    _finish(run)
    return run.report


# ---------------------------------------------------------------- stages
def _teach(run: _Run, true_task: AssemblyTask) -> AssemblyTask:
    with run.stage("teach") as d:
        teacher = run.plugin("teacher")
        camera_file = run.cfg.path(run.cfg.camera) if run.cfg.camera else None
        frames, camera = teacher.demonstrate(true_task, run.cfg.demo, camera_file, run.out / "demonstration")
        d["frames"] = len(frames)
        learned = teacher.teach(frames, camera, true_task)
        err = pose_error(learned.T_A_B, true_task.T_A_B)
        v_true = np.asarray(true_task.v_a, float)
        v_err = float(np.degrees(np.arccos(np.clip(np.dot(learned.v_a, v_true) / np.linalg.norm(v_true), -1, 1))))
        d.update(T_A_B_error_mm=round(err.position_mm, 4), T_A_B_error_deg=round(err.angle_deg, 4),
                 v_a_error_deg=round(v_err, 4))
        run.report.task = learned
        run.report.metrics.update(teach_position_mm=err.position_mm, teach_angle_deg=err.angle_deg,
                                  teach_v_a_deg=v_err)
        write_model(run.out / "task.json", learned)
        run.artefact("task", run.out / "task.json", "json")
        return learned


def _spawn(run: _Run, robot: Robot, a: PartModel, b: PartModel, table: TablePlane) -> dict[str, np.ndarray]:
    with run.stage("spawn") as d:
        rng = np.random.default_rng([run.cfg.seed, 11])
        T_a, T_b = random_start_poses([a, b], table.height, run.execution.scene, rng)
        robot.reset_world(table, {a.name: (a, T_a), b.name: (b, T_b)})
        # the simulator's poses are the truth (a part may settle slightly)
        truth = {a.name: robot.part_pose(a.name), b.name: robot.part_pose(b.name)}
        for name, T in truth.items():
            d[name] = geometry.to_xyz_mm_rpy_deg(T)
        return truth


def _detect(run: _Run, robot: Robot, parts: tuple[PartModel, ...], table: TablePlane,
            truth: dict[str, np.ndarray]) -> dict[str, Detection]:
    with run.stage("detect", total=len(parts)) as d:
        detector = run.plugin("detector")
        corrector = run.plugin("corrector") if run.cfg.corrector is not None else None
        depth, cloud, viewpoint = _sense(robot, run.execution.depth_frames)
        np.save(run.out / "depth.npy", depth.astype(np.float32))
        out: dict[str, Detection] = {}
        for part in parts:
            detector.prepare(part)
            det = detect_and_correct(detector, corrector, cloud, part, table, viewpoint=viewpoint)
            if not det.found or det.rough is None:
                run.report.detections.append(det)
                raise StageFailed(f"{part.name} not found: {det.reason}")
            if "correction_error" in det.details:
                run.report.detections.append(det)
                raise StageFailed(f"{part.name} found but not corrected: {det.details['correction_error']}")
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


def _sense(robot: Robot, frames: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """``(depth image, cloud (n, 3) world frame, camera centre or None)`` from the robot's depth camera.

    The clouds of ``frames`` depth frames are stacked (the parts stand still;
    the sensor's noise is new in every frame, so the detector's voxel filter
    and ICP average it out); the depth image is the first frame's.
    """
    depth, cloud = robot.sense_depth()
    if frames > 1:
        cloud = np.concatenate([cloud] + [robot.sense_depth()[1] for _ in range(frames - 1)])
    try:
        viewpoint = robot.camera_pose()[:3, 3]
    except NotImplementedError:
        viewpoint = None
    return depth, cloud, viewpoint


def _grasps(run: _Run, robot: Robot, a: PartModel, b: PartModel) -> dict[str, list]:
    with run.stage("grasps", total=2) as d:
        planner = run.plugin("grasp_planner")
        out = {}
        for part in (a, b):
            gs = planner.plan(part, robot.hand)
            if not gs:
                raise StageFailed(f"no force-closure grasp of {part.name} for this hand")
            out[part.name] = gs
            d[part.name] = len(gs)
            run.hook("asmteach_stage_progress", stage="grasps", advance=1, message=part.name)
        return out


def _plan(run: _Run, robot: Robot, task: AssemblyTask, a: PartModel, b: PartModel,
          detections: dict[str, Detection], grasps: dict[str, list], table: TablePlane) -> Any:
    with run.stage("plan") as d:
        planner = run.plugin("assembly_planner")
        motion = run.plugin("motion_planner")
        problem = AssemblyProblem(a, b, task, detections[a.name].best, detections[b.name].best,
                                  grasps[a.name], grasps[b.name], table)
        result = planner.plan(problem, robot, motion, progress=run.progress("plan"))
        for name, path in planner.write_figures(result, run.out).items():
            run.artefact(name, path, "png")
        run.report.plan_stats = to_jsonable(result.plan.stats)
        d.update(segments=len(result.plan.segments),
                 planning_seconds=result.plan.stats.get("planning_seconds"),
                 execution_seconds=result.plan.stats.get("execution_seconds"))
        write_model(run.out / "plan.json", result.plan)
        run.artefact("plan", run.out / "plan.json", "json")
        if not result.success:
            raise StageFailed(result.reason or "assembly planning failed", {"failed_at": result.failed_at})
        if run.execution.recheck_plan:
            try:
                chk = robot.verify_plan(result.plan, {a.name: (a, problem.T_world_a), b.name: (b, problem.T_world_b)},
                                        table)
            except NotImplementedError:
                chk = None
            if chk is not None:
                # Recorded, not fatal: execution and measurement say whether the parts got assembled.
                d["recheck"] = chk.summary()
                run.report.metrics["plan_recheck_collisions"] = len(chk.collisions)
        return result


def _look_again(run: _Run, robot: Robot, task: AssemblyTask, parts: tuple[PartModel, PartModel],
                detections: dict[str, Detection], grasps: dict[str, list], table: TablePlane, result: Any,
                rest: Plan) -> tuple[Any, Plan]:
    """Detect A again now that it stands at its goal; plan again from what is seen. Returns the result and plan to
    carry on with.

    - A is not at its goal (beyond the success tolerance): its first detection
      was the other twin of an ambiguous pair (the block turned over with its
      hole on the far side; at the goal the camera sees the face that tells
      them apart). The assembly is planned again with A's start where it is.
    - A is there, but B's assembled pose at the A that is seen is more than
      ``reaim_mm`` / ``reaim_deg`` from the planned one (a detection or
      placement error that eats the hole's clearance): B's insertion is
      planned again into the A that is seen (:meth:`AssemblyPlanner.plan_insertion`).
      If that fails, the plan B already has goes on.
    - Otherwise the rest of the plan goes on.
    """
    a, b = parts
    ex = run.execution
    with run.stage("look_again") as d:
        detector = run.plugin("detector")
        _, cloud, viewpoint = _sense(robot, ex.depth_frames)
        corrector = run.plugin("corrector") if run.cfg.corrector is not None else None
        det = detect_and_correct(detector, corrector, cloud, a, table, viewpoint=viewpoint)
        if not det.found or det.rough is None:
            if detections[a.name].details.get("ambiguous"):
                raise StageFailed(f"{a.name} not found again at its goal: {det.reason}")
            d["not_found"] = det.reason  # nothing to decide: the plan goes on as it was
            return result, rest
        T = det.best
        if "correction_error" in det.details:
            d["correction_error"] = det.details["correction_error"]  # the rough pose is all there is
        T_near = nearest_symmetric(T, result.T_world_a_goal, run.symmetries(a))  # the same solid, nearest the goal
        err = pose_error(T_near, result.T_world_a_goal)
        d["a_vs_goal"] = err.short(3)
        d["T_world_a_seen"] = T_near.tolist()
        # the simulator's truth, to tell placing errors from detection errors in the report
        T_true = robot.part_pose(a.name)
        truth = pose_error(T_true, result.T_world_a_goal, (), run.symmetries(a))
        d["a_true_vs_goal"] = truth.short(3)
        d["T_world_a_true"] = T_true.tolist()
        d["still_ambiguous"] = bool(det.details.get("ambiguous"))
        planner, motion = run.plugin("assembly_planner"), run.plugin("motion_planner")
        problem = AssemblyProblem(a, b, task, T, detections[b.name].best, grasps[a.name], grasps[b.name], table)
        d["replanned"] = d["reaimed"] = False
        if err.position_mm <= ex.success_a_goal_mm and err.angle_deg <= ex.success_angle_deg:
            b_off = pose_error(T_near @ task.T_A_B, result.T_world_a_goal @ task.T_A_B)
            d["b_goal_shift"] = b_off.short(3)
            if b_off.position_mm <= ex.reaim_mm and b_off.angle_deg <= ex.reaim_deg:
                return result, rest
            try:
                new = planner.plan_insertion(problem, robot, motion, T_world_a=T_near,
                                             progress=run.progress("look_again"))
            except NotImplementedError:
                d["reaim"] = "the assembly planner cannot plan B alone; the plan goes on"
                return result, rest
            if not new.success:
                d["reaim"] = f"planning B into the A seen failed ({new.reason}); the plan goes on"
                return result, rest
            d["reaimed"] = True
            _write_plan_again(run, new.plan)
            return result, new.plan
        d["replanned"] = True
        new = planner.plan(problem, robot, motion, progress=run.progress("look_again"))
        _write_plan_again(run, new.plan)
        d["segments"] = len(new.plan.segments)
        if not new.success:
            raise StageFailed(f"{a.name} is not at its goal ({err.position_mm:.1f} mm / {err.angle_deg:.1f} deg "
                              f"off) and planning again failed: {new.reason}", {"failed_at": new.failed_at})
        return new, new.plan


def _write_plan_again(run: _Run, plan: Plan) -> None:
    write_model(run.out / "plan_again.json", plan)
    run.artefact("plan_again", run.out / "plan_again.json", "json")


def _execute(run: _Run, robot: Robot, plan: Plan, stage: str = "execute") -> list[np.ndarray]:
    frames: list[np.ndarray] = []
    with run.stage(stage, total=len(plan.segments)) as d:
        record = run.execution.animation
        period = 1.0 / run.execution.animation_fps
        if record:
            try:
                frames.append(robot.sense_rgb())
            except NotImplementedError:  # World.sense_rgb is optional: no colour camera, no animation
                record = False
                d["animation"] = f"not recorded: {type(robot).__name__} has no colour camera"
        trace = _ExecutionTrace(robot)
        d["trace"] = trace.events
        for seg in plan.segments:
            if seg.trajectory is not None:
                for chunk in _chunks(seg.trajectory, period if record else None):
                    robot.execute(chunk)
                    if record:
                        frames.append(robot.sense_rgb())
                trace.after_path(seg.trajectory, seg.label)
                _count_robot_seconds(run.report, seg)
            elif seg.gripper is not None:
                ev = seg.gripper
                close = ev.action == "close"
                trace.before_grip(seg.label, ev.arm, close, ev.attach)
                ok = robot.grip(ev.arm, close, ev.attach)
                if close and not ok:
                    raise StageFailed(f"{seg.label}: the fingers did not close on the part")
                trace.after_grip(ev.arm, close, ev.attach)
            run.hook("asmteach_stage_progress", stage="execute", advance=1, message=seg.label)
        d["segments"] = len(plan.segments)
        d["frames_recorded"] = len(frames)
        d["max_tracking_error_rad"] = trace.max_tracking_error
    return frames


def _count_robot_seconds(report: RunReport, seg: Any) -> None:
    """Add an executed motion's duration (simulated seconds) to the report's robot clock, in total and by kind."""
    seconds = float(seg.trajectory.times[-1] - seg.trajectory.times[0])
    clock = report.robot_seconds
    clock["total"] = round(clock.get("total", 0.0) + seconds, 3)
    kind = seg.kind or "unlabelled"
    clock[kind] = round(clock.get(kind, 0.0) + seconds, 3)


class _ExecutionTrace:
    """What happened to the parts during execution, against what the plan assumed.

    One event per gripper action: the part's pose (mm, deg); on close, how far
    it moved since its release (toppled, pushed); on release, how far it
    slipped in the hand while held, the label of the motion before, and how
    far it dropped when let go (mm).
    """

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self.events: list[dict[str, Any]] = []
        self.held: dict[str, str] = {}  # arm -> part
        self.T_tcp_part: dict[str, np.ndarray] = {}  # part -> its pose in the hand at the close
        self.T_released: dict[str, np.ndarray] = {}  # part -> T_world_part after its last release
        self.max_tracking_error = 0.0
        self.last_path: dict[str, str] = {}  # arm -> label of its last motion

    def _tcp(self, arm: str) -> np.ndarray:
        return self.robot.fk(arm, self.robot.current(arm))

    def after_path(self, traj: Any, label: str) -> None:
        err = float(np.max(np.abs(self.robot.current(traj.arm) - np.asarray(traj.positions)[-1])))
        self.max_tracking_error = max(self.max_tracking_error, err)
        self.last_path[traj.arm] = label

    def before_grip(self, label: str, arm: str, close: bool, part: str | None) -> None:
        part = part if close else self.held.get(arm)
        ev: dict[str, Any] = {"label": label}
        if part is not None:
            T = self.robot.part_pose(part)
            ev.update(part=part, **geometry.to_xyz_mm_rpy_deg(T))
            if close and part in self.T_released:
                moved = geometry.translation_distance(T, self.T_released[part])
                ev["moved_since_release_mm"] = round(1000.0 * moved, 2)
            if not close and part in self.T_tcp_part:
                T_expected = self._tcp(arm) @ self.T_tcp_part[part]
                ev["slip_in_hand_mm"] = round(1000.0 * geometry.translation_distance(T, T_expected), 2)
                ev["after"] = self.last_path.get(arm, "")
        self.events.append(ev)

    def after_grip(self, arm: str, close: bool, part: str | None) -> None:
        if close and part is not None:
            self.held[arm] = part
            self.T_tcp_part[part] = geometry.invert(self._tcp(arm)) @ self.robot.part_pose(part)
            return
        part = self.held.pop(arm, None)
        if part is not None:
            T = self.robot.part_pose(part)
            before = self.events[-1]
            moved = np.subtract(T[:3, 3] * 1000.0, before.get("xyz_mm", T[:3, 3] * 1000.0))
            before["dropped_mm"] = round(float(np.linalg.norm(moved)), 2)
            self.T_released[part] = T


def _chunks(traj: Any, period: float | None) -> list[Any]:
    """Split a trajectory into pieces of about ``period`` seconds (for animation frames)."""
    if period is None or traj.times[-1] <= period:
        return [traj]
    times = np.asarray(traj.times)
    cuts = [0]
    next_t = period
    for i, t in enumerate(times):
        if t >= next_t:
            cuts.append(i)
            next_t = t + period
    if cuts[-1] != len(times) - 1:
        cuts.append(len(times) - 1)
    out = []
    for i0, i1 in itertools.pairwise(cuts):
        if i1 <= i0:
            continue
        t = times[i0 : i1 + 1] - times[i0]
        out.append(type(traj)(arm=traj.arm, joint_names=traj.joint_names, times=t.tolist(),
                              positions=np.asarray(traj.positions)[i0 : i1 + 1]))
    return out


def _measure(run: _Run, robot: Robot, learned: AssemblyTask, true_task: AssemblyTask, a: PartModel, b: PartModel,
             result: Any) -> None:
    with run.stage("measure") as d:
        T_a, T_b = robot.part_pose(a.name), robot.part_pose(b.name)
        T_A_B = geometry.invert(T_a) @ T_b
        # A symmetric part may be detected, and so assembled, in any of its symmetric poses.
        sym_a, sym_b = run.symmetries(a), run.symmetries(b)
        vs_taught = pose_error(T_A_B, learned.T_A_B, sym_a, sym_b)
        vs_true = pose_error(T_A_B, true_task.T_A_B, sym_a, sym_b)
        a_goal_mm = pose_error(T_a, result.T_world_a_goal, (), sym_a).position_mm
        ex = run.execution
        ok = (vs_taught.position_mm <= ex.success_position_mm and vs_taught.angle_deg <= ex.success_angle_deg
              and a_goal_mm <= ex.success_a_goal_mm)
        run.report.metrics.update(
            achieved_vs_taught_mm=vs_taught.position_mm, achieved_vs_taught_deg=vs_taught.angle_deg,
            achieved_vs_true_mm=vs_true.position_mm, achieved_vs_true_deg=vs_true.angle_deg,
            a_goal_error_mm=a_goal_mm,
        )
        d.update({k: round(v, 3) for k, v in run.report.metrics.items() if k.startswith(("achieved", "a_goal"))})
        write_json(run.out / "achieved.json", {"T_world_A": T_a.tolist(), "T_world_B": T_b.tolist(),
                                               "T_A_B": T_A_B.tolist(), "T_A_B_taught": learned.T_A_B.tolist(),
                                               "T_A_B_true": true_task.T_A_B.tolist()})
        run.report.success = bool(ok)
        if not ok:
            raise StageFailed(
                f"assembled outside tolerance: B in A off by {vs_taught.position_mm:.2f} mm / "
                f"{vs_taught.angle_deg:.2f} deg (limits {ex.success_position_mm} mm / {ex.success_angle_deg} deg), "
                f"A {a_goal_mm:.2f} mm from its goal (limit {ex.success_a_goal_mm} mm)" + _worst_slip(run.report)
            )


SLIP_NOTE_MM = 1.0
"""A part this far (mm) from where the hand should hold it at its release was pushed in the hand: the motion
before the release met resistance (a jam on an insertion, a collision); the failure reason names it."""


def _worst_slip(report: RunReport) -> str:
    """``"; <part> was pushed N mm in the hand before '<release>'"`` for the worst such release, else ``""``."""
    events = [ev for st in report.stages if st.stage in ("execute_a", "execute")
              for ev in (st.details or {}).get("trace", []) if ev.get("slip_in_hand_mm", 0.0) > SLIP_NOTE_MM]
    if not events:
        return ""
    ev = max(events, key=lambda e: e["slip_in_hand_mm"])
    return (f"; {ev.get('part', 'the part')} was pushed {ev['slip_in_hand_mm']:.1f} mm in the hand by "
            f"{ev.get('after') or ev['label']!r} (it met resistance there: a jam, if that is the insertion)")


def _write_animation(run: _Run, frames: list[np.ndarray]) -> None:
    from PIL import Image

    from asmteach.core.io import atomic_path

    path = run.out / "execution.gif"
    images = [Image.fromarray(np.asarray(f, dtype=np.uint8)) for f in frames]
    with atomic_path(path) as tmp:
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:],
                       duration=int(1000 / run.execution.animation_fps), loop=0)
    run.artefact("animation", path, "gif")


def _finish(run: _Run) -> None:
    from asmteach.core.run_figures import metrics_figure

    # the computer's clock beside the robot's: wall seconds per stage (a stage run twice is summed)
    clock: dict[str, float] = {}
    for st in run.report.stages:
        clock[st.stage] = round(clock.get(st.stage, 0.0) + st.seconds, 3)
    clock["total"] = round(sum(st.seconds for st in run.report.stages), 3)
    run.report.computer_seconds = clock
    if run.report.metrics:
        path = metrics_figure(run.out / "errors.png", run.report)
        run.artefact("errors", path, "png")
    write_model(run.out / "report.json", run.report)
    extra = run.hook("asmteach_report_ready", report=run.report.model_dump(mode="json"), out_dir=run.out)
    for paths in extra or []:
        for p in paths or []:
            run.report.artefacts.setdefault(Path(p).name, str(p))
    try:
        from asmteach.core.report_html import write_report_html
    except ImportError:  # pragma: no cover - the HTML writer ships with the core
        write_report_html = None
    if write_report_html is not None:
        html = write_report_html(run.report, run.out)
        run.report.artefacts["html"] = str(Path(html).relative_to(run.out))
    write_model(run.out / "report.json", run.report)
