"""What happened to the parts during execution (:class:`ExecutionTrace`), against what the plan assumed.

The execute stage calls it around every motion and gripper action; the measure stage reads its events to
name why a run failed (a jam with its depth and force, a part toppled or pushed by a named motion at a time
on the robot's clock). Units in the events: millimetres, degrees, newtons, seconds (the robot's clock from
the run's first motion).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from asmteach.core import geometry
from asmteach.core.arm.insertion_records import InsertionOutcome
from asmteach.core.interfaces import Robot
from asmteach.core.models import Plan

__all__ = ["MOVED_MM", "TOPPLED_DEG", "ExecutionTrace", "plan_parts"]

MOVED_MM = 1.0
"""A part no hand holds that moves this far (mm) during a motion was pushed (or slid, or fell): an event."""

TOPPLED_DEG = 20.0
"""A part no hand holds whose up axis turns this far (deg) during a motion toppled."""


def plan_parts(plan: Plan) -> list[str]:
    """The parts a plan moves or grasps, in the order it first names them."""
    names: list[str] = []
    for seg in plan.segments:
        for name in (seg.part, seg.gripper.attach if seg.gripper else None):
            if name and name not in names:
                names.append(name)
    return names


def _tilt_deg(T0: np.ndarray, T1: np.ndarray) -> float:
    """How far (deg) the part's axis that pointed up (world z) at ``T0`` has turned away from up at ``T1``."""
    up_in_part = T0[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    now = T1[:3, :3] @ up_in_part
    return float(np.degrees(np.arccos(np.clip(now[2], -1.0, 1.0))))


class ExecutionTrace:
    """Events of one execution (``events``, JSON-ready).

    One event per gripper action: the part's pose (mm, deg); on close, how far
    it moved since its release (toppled, pushed); on release, how far it
    slipped in the hand while held, the label and kind (``after_kind``:
    transit, approach, insertion, regrasp or None) of the motion before, and
    how far it dropped and tilted when let go (mm, deg). One event per motion
    that moved a part no hand held (``pushed_mm``, ``tilted_deg``,
    ``toppled``, ``by`` the motion, its kind, ``t_s`` when the motion started).
    One event per guarded insertion (``insertion``: its
    :meth:`~asmteach.core.arm.insertion_records.InsertionOutcome.as_dict`, ``t_s``,
    and the poses the measure stage splits the insertion error with).
    """

    def __init__(
        self,
        robot: Robot,
        parts: list[str] | None = None,
        t0_s: float = 0.0,
        believed: dict[str, np.ndarray] | None = None,
    ) -> None:
        self.robot = robot
        # Where the plan believes each part is (T_world_part, from its detection), carried along by the hand that
        # holds it: a part's measured pose in the hand against this is what the plan did not know.
        self.believed: dict[str, np.ndarray] = {k: np.asarray(v, dtype=float) for k, v in (believed or {}).items()}
        self.believed_in_hand: dict[str, np.ndarray] = {}  # part -> T_tcp_part as the plan believes it held
        self.parts = list(parts or [])
        self.events: list[dict[str, Any]] = []
        self.held: dict[str, str] = {}  # arm -> part
        self.T_tcp_part: dict[str, np.ndarray] = {}  # part -> its pose in the hand at the close
        self.T_released: dict[str, np.ndarray] = {}  # part -> T_world_part after its last release
        self.max_tracking_error = 0.0
        self.last_path: dict[str, str] = {}  # arm -> label of its last motion
        self.last_kind: dict[str, str | None] = {}  # arm -> kind of its last motion (PlanSegment.kind)
        self.t_s = float(t0_s)  # the robot's clock: seconds of motion executed so far in the run
        self._before: dict[str, np.ndarray] = {}  # free part -> its pose when the current motion started
        self._grip_pose = np.eye(4)  # the released part's pose just before its last release

    def _tcp(self, arm: str) -> np.ndarray:
        return self.robot.fk(arm, self.robot.current(arm))

    def free_parts(self) -> list[str]:
        held = set(self.held.values())
        return [p for p in self.parts if p not in held]

    def other_part(self, part: str) -> str | None:
        """The one other part of the plan (what ``part`` is inserted into), or None when there are several."""
        others = [p for p in self.parts if p != part]
        return others[0] if len(others) == 1 else None

    def before_path(self) -> None:
        self._before = {p: self.robot.part_pose(p) for p in self.free_parts()}

    def after_path(self, traj: Any, label: str, kind: str | None = None, seconds: float | None = None) -> None:
        """After a motion of ``seconds`` (default: the trajectory's own): tracking error, and every free part
        the motion moved (pushed, toppled) as an event."""
        err = float(np.max(np.abs(self.robot.current(traj.arm) - np.asarray(traj.positions)[-1])))
        self.max_tracking_error = max(self.max_tracking_error, err)
        self.last_path[traj.arm] = label
        self.last_kind[traj.arm] = kind
        start = self.t_s
        self.t_s += float(traj.times[-1] - traj.times[0]) if seconds is None else float(seconds)
        for part, T0 in self._before.items():
            T1 = self.robot.part_pose(part)
            moved = 1000.0 * geometry.translation_distance(T0, T1)
            tilt = _tilt_deg(T0, T1)
            if moved > MOVED_MM or tilt > TOPPLED_DEG:
                self.events.append(
                    {
                        "label": label,
                        "part": part,
                        "pushed_mm": round(moved, 2),
                        "tilted_deg": round(tilt, 2),
                        "toppled": tilt > TOPPLED_DEG,
                        "by": label,
                        "by_kind": kind,
                        "holding": self.held.get(traj.arm),
                        "t_s": round(start, 3),
                    }
                )
        self._before = {}

    def insertion(
        self,
        label: str,
        part: str,
        other: str | None,
        outcome: InsertionOutcome,
        T_tcp_start: np.ndarray,
        T_tcp_end: np.ndarray,
    ) -> None:
        """Record a guarded insertion: its outcome, when it started, and the poses to split its error with
        (the planned TCP line ``T_world_tcp_start`` to ``T_world_tcp_end``, ``T_tcp_part`` in the hand and
        ``T_world_other`` as it began)."""
        ev: dict[str, Any] = {
            "label": label,
            "part": part,
            "other": other,
            "insertion": outcome.as_dict(),
            "t_s": round(self.t_s, 3),
            "T_world_tcp_start": np.asarray(T_tcp_start).tolist(),
            "T_world_tcp_end": np.asarray(T_tcp_end).tolist(),
        }
        if part in self.T_tcp_part:
            ev["T_tcp_part"] = self.T_tcp_part[part].tolist()
        if other is not None and other in self._before:
            ev["T_world_other"] = self._before[other].tolist()
        self.events.append(ev)

    def before_grip(self, label: str, arm: str, close: bool, part: str | None) -> None:
        part = part if close else self.held.get(arm)
        ev: dict[str, Any] = {"label": label, "t_s": round(self.t_s, 3)}
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
                ev["after_kind"] = self.last_kind.get(arm)
            self._grip_pose = T
        self.events.append(ev)

    def after_grip(self, arm: str, close: bool, part: str | None) -> None:
        if part is not None and part not in self.parts:
            self.parts.append(part)
        if close and part is not None:
            self.held[arm] = part
            self.T_tcp_part[part] = geometry.invert(self._tcp(arm)) @ self.robot.part_pose(part)
            if part in self.believed:
                self.believed_in_hand[part] = geometry.invert(self._tcp(arm)) @ self.believed[part]
            return
        part = self.held.pop(arm, None)
        if part is not None:
            T = self.robot.part_pose(part)
            before = self.events[-1]
            moved = np.subtract(T[:3, 3] * 1000.0, before.get("xyz_mm", T[:3, 3] * 1000.0))
            before["dropped_mm"] = round(float(np.linalg.norm(moved)), 2)
            before["tilted_deg"] = round(_tilt_deg(self._grip_pose, T), 2)
            self.T_released[part] = T
            if part in self.believed_in_hand:
                # the plan lets a part go a little above where it rests: it believes it landed (the drop seen)
                B = self._tcp(arm) @ self.believed_in_hand.pop(part)
                B[2, 3] += T[2, 3] - self._grip_pose[2, 3]
                self.believed[part] = B
