"""The measure stage: the achieved T_A_B against the taught and the true one (mm, deg), and success.

A part with an axis of revolution (a round peg, a pin) assembled turned about that axis is the same solid in
the same place: its error leaves that turn out (:func:`assembly_error`). The symmetry group alone samples
such turns every 10 deg (:func:`~asmteach.core.symmetry.part_symmetries`), which left up to 5 deg of a turn
that changes nothing in the measured angle (round_peg s0_0 seed 8: 2.52 deg, of which 0.64 deg tilt).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from asmteach.core import geometry
from asmteach.core.interfaces import PartModel, Robot
from asmteach.core.io import write_json
from asmteach.core.models import AssemblyTask
from asmteach.core.pipeline.causes import failure_story, insertion_error
from asmteach.core.pipeline.stage import Run, StageFailed
from asmteach.core.pose_error import PoseError, nearest_symmetric, pose_error
from asmteach.core.symmetry import SymmetryFinder, axis_rotations, principal_frame

__all__ = ["assembly_error", "measure_stage", "revolution_axis", "untwisted"]


def revolution_axis(part: PartModel, tol: float = 0.0005) -> np.ndarray | None:
    """The unit axis (part frame) of ``part``'s surface of revolution through its centre of mass, or None.

    A principal axis about which turns of 7 and 31 deg map the surface onto itself within ``tol`` metres
    (the test :func:`~asmteach.core.symmetry.equivalent_transforms` uses).
    """
    mesh = part.mesh
    com = np.asarray(part.center_of_mass, dtype=float)
    finder = SymmetryFinder(mesh, np.asarray(mesh.convex_hull.vertices), com, tol=tol, corners=False)
    for axis in principal_frame(mesh).T:
        if all(finder.maps(R) for R in axis_rotations(axis, np.radians([7.0, 31.0]))):
            return axis / np.linalg.norm(axis)
    return None


def _twist(R: np.ndarray, axis: np.ndarray) -> float:
    """The angle (radians) of ``R``'s turn about ``axis`` (swing-twist split of its quaternion)."""
    q = geometry.to_quat(geometry.from_rotation(R))  # x y z w
    return float(2.0 * np.arctan2(np.dot(q[:3], axis), q[3]))


def assembly_error(
    T_A_B: np.ndarray,
    T_A_B_ref: np.ndarray,
    sym_a: Sequence[np.ndarray] = (),
    sym_b: Sequence[np.ndarray] = (),
    axis_b: np.ndarray | None = None,
    com_b: np.ndarray | None = None,
) -> PoseError:
    """``T_A_B`` (metres) against the nearest of its symmetric references, as :func:`pose_error`; with B's
    axis of revolution ``axis_b`` through ``com_b`` (B's frame), the reference is also turned about that axis
    to meet ``T_A_B`` (the turn maps B onto itself), so only B's tilt and offset count."""
    if axis_b is None:
        return pose_error(T_A_B, T_A_B_ref, sym_a, sym_b)
    refs = [nearest_symmetric(np.linalg.inv(S) @ T_A_B_ref, T_A_B, sym_b) for S in (sym_a or [np.eye(4)])]
    errors = [pose_error(T_A_B, ref) for ref in refs]
    k = int(np.argmin([e.position_mm + e.angle_deg for e in errors]))
    return pose_error(T_A_B, untwisted(refs[k], T_A_B, axis_b, com_b))


def untwisted(T_ref: np.ndarray, T: np.ndarray, axis: np.ndarray, com: np.ndarray | None = None) -> np.ndarray:
    """``T_ref`` turned about the part's ``axis`` of revolution through ``com`` (part frame, metres) by the
    turn about it that ``T`` has against ``T_ref``: the same solid in the same place, nearest ``T``."""
    c = np.zeros(3) if com is None else np.asarray(com, dtype=float)
    E = np.linalg.inv(T_ref) @ np.asarray(T, dtype=float)  # T against the reference, in the part's frame
    R = axis_rotations(axis, np.array([_twist(E[:3, :3], axis)]))[0]
    return np.asarray(T_ref, dtype=float) @ geometry.from_rotation(R, c - R @ c)


def measure_stage(
    run: Run, robot: Robot, learned: AssemblyTask, true_task: AssemblyTask, a: PartModel, b: PartModel, result: Any
) -> None:
    with run.stage("measure") as d:
        T_a, T_b = robot.part_pose(a.name), robot.part_pose(b.name)
        T_A_B = geometry.invert(T_a) @ T_b
        # A symmetric part may be detected, and so assembled, in any of its symmetric poses.
        sym_a, sym_b = run.symmetries(a), run.symmetries(b)
        axis_b, com_b = revolution_axis(b), np.asarray(b.center_of_mass, dtype=float)
        vs_taught = assembly_error(T_A_B, learned.T_A_B, sym_a, sym_b, axis_b, com_b)
        vs_true = assembly_error(T_A_B, true_task.T_A_B, sym_a, sym_b, axis_b, com_b)
        a_goal_mm = pose_error(T_a, result.T_world_a_goal, (), sym_a).position_mm
        ex = run.execution
        ok = (
            vs_taught.position_mm <= ex.success_position_mm
            and vs_taught.angle_deg <= ex.success_angle_deg
            and a_goal_mm <= ex.success_a_goal_mm
        )
        run.report.metrics.update(
            achieved_vs_taught_mm=vs_taught.position_mm,
            achieved_vs_taught_deg=vs_taught.angle_deg,
            achieved_vs_true_mm=vs_true.position_mm,
            achieved_vs_true_deg=vs_true.angle_deg,
            a_goal_error_mm=a_goal_mm,
        )
        d.update({k: round(v, 3) for k, v in run.report.metrics.items() if k.startswith(("achieved", "a_goal"))})
        write_json(
            run.out / "achieved.json",
            {
                "T_world_A": T_a.tolist(),
                "T_world_B": T_b.tolist(),
                "T_A_B": T_A_B.tolist(),
                "T_A_B_taught": learned.T_A_B.tolist(),
                "T_A_B_true": true_task.T_A_B.tolist(),
            },
        )
        split = insertion_error(run.report, learned, true_task, result.T_world_a_goal, sym_a)
        if split is not None:
            d["insertion_error"] = split
        run.report.success = bool(ok)
        if not ok:
            note, cause, evidence = failure_story(run.report, split)
            run.report.failure_details = evidence
            raise StageFailed(
                f"assembled outside tolerance: B in A off by {vs_taught.position_mm:.2f} mm / "
                f"{vs_taught.angle_deg:.2f} deg (limits {ex.success_position_mm} mm / {ex.success_angle_deg} deg), "
                f"A {a_goal_mm:.2f} mm from its goal (limit {ex.success_a_goal_mm} mm); " + note,
                details={"failure": evidence},
                cause=cause,
            )
