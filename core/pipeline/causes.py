"""Why an assembly ended outside tolerance, named from the execution trace's evidence (issue 23, item 5).

:func:`failure_story` reads the events :class:`~asmteach.core.pipeline.monitor.ExecutionTrace` recorded and
names what happened, most telling first: a guarded insertion that jammed (depth, contact force, time) -
led by what knocked the part it went into before it met it (:func:`jam_story`) -, a
part that toppled or was pushed by a named motion (how far, when), a part pushed in the hand, a part that
tilted or dropped when let go; with nothing of that, where the insertion's error came from
(:func:`insertion_error`). A failure that says only "N mm from its goal" names no cause. Units: mm, deg, N,
seconds on the robot's clock (motion executed since the run's first motion).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from asmteach.core.failures import FailureCause
from asmteach.core.models import AssemblyTask, RunReport
from asmteach.core.pose_error import nearest_symmetric

__all__ = [
    "KNOCKED_MM",
    "RELEASE_DROP_MM",
    "RELEASE_TILT_DEG",
    "SAME_DEPTH_MM",
    "SLIP_NOTE_MM",
    "failure_story",
    "insertion_error",
    "jam_note",
    "jam_story",
    "knocked_before",
]

SLIP_NOTE_MM = 1.0
"""A part this far (mm) from where the hand should hold it at its release was pushed in the hand: the motion
before the release met resistance (a jam on an insertion, a collision)."""

RELEASE_TILT_DEG = 1.0
"""A part that tilts this far (deg) as the hand lets it go settled somewhere the plan did not put it (it leans
in its hole's clearance, slides off a support)."""

KNOCKED_MM = 3.0
"""A free part that a motion before an insertion moved this far (mm; A's goal tolerance) was knocked off the pose
the insertion was planned for: a jam that follows is its consequence, not its cause."""

SAME_DEPTH_MM = 1.0
"""Resistance met within this depth span (mm) through sideways shifts of twice as much is named: the search
changed nothing in where the part stopped."""

RELEASE_DROP_MM = 2.0
"""A part that drops this far (mm) as the hand lets it go fell (a placement is planned ~1 mm above its rest)."""


def _events(report: RunReport) -> list[dict[str, Any]]:
    return [
        ev for st in report.stages if st.stage in ("execute_a", "execute") for ev in (st.details or {}).get("trace", [])
    ]


def _worst_slip(report: RunReport) -> dict[str, Any] | None:
    """The release event with the largest slip in the hand beyond :data:`SLIP_NOTE_MM`, else None."""
    events = [ev for ev in _events(report) if ev.get("slip_in_hand_mm", 0.0) > SLIP_NOTE_MM]
    return max(events, key=lambda e: e["slip_in_hand_mm"]) if events else None


def _t(ev: dict[str, Any]) -> str:
    return f"t = {ev['t_s']:.1f} s" if ev.get("t_s") is not None else "an unrecorded time"


def _lateral(v: np.ndarray, d: np.ndarray) -> float:
    """Length (mm) of ``v`` (metres) across the direction ``d``."""
    return 1000.0 * float(np.linalg.norm(v - np.dot(v, d) * d))


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0))))


def insertion_error(
    report: RunReport,
    learned: AssemblyTask,
    true_task: AssemblyTask,
    T_world_a_goal: np.ndarray,
    sym_a: Sequence[np.ndarray] = (),
) -> dict[str, float] | None:
    """Where the part being inserted was, across the insertion line, when the insertion began, and why.

    From the last insertion event: the part's end pose had the arm gone as planned (planned TCP end @ the part
    in the hand), against the true seat (A's pose then @ the true T_A_B). Split into what the hand held it
    off by (``grasp``: the part's detection, its regrasps and the grasp itself, against the plan's B goal,
    A's goal @ taught T_A_B), where A stood against its goal (``a_place``) and the taught T_A_B against the true
    one (``taught``). Each as ``<name>_mm`` across the insertion line and ``<name>_deg`` of the part's
    insertion axis; ``total_mm``/``total_deg`` part against seat. A symmetric A (``sym_a``, part-frame
    symmetries) is taken in its pose nearest its goal. None without an insertion event.
    """
    evs = [e for e in _events(report) if "insertion" in e and "T_tcp_part" in e and "T_world_other" in e]
    if not evs:
        return None
    ev = evs[-1]
    T_start, T_end = np.asarray(ev["T_world_tcp_start"]), np.asarray(ev["T_world_tcp_end"])
    line = T_end[:3, 3] - T_start[:3, 3]
    if np.linalg.norm(line) < 1e-9:
        return None
    d = line / np.linalg.norm(line)
    T_a = nearest_symmetric(np.asarray(ev["T_world_other"]), T_world_a_goal, sym_a)
    E = T_end @ np.asarray(ev["T_tcp_part"])  # the part where the planned motion takes it
    G = np.asarray(T_world_a_goal) @ learned.T_A_B  # where the plan meant it to go
    M = T_a @ learned.T_A_B  # the taught seat in A as it stands
    H = T_a @ true_task.T_A_B  # the true seat
    axis = H[:3, :3].T @ d  # the insertion axis in the part's frame
    out = {
        "total_mm": _lateral(E[:3, 3] - H[:3, 3], d),
        "total_deg": _angle(E[:3, :3] @ axis, d),
        "grasp_mm": _lateral(E[:3, 3] - G[:3, 3], d),
        "grasp_deg": _angle(E[:3, :3] @ axis, G[:3, :3] @ axis),
        "a_place_mm": _lateral(M[:3, 3] - G[:3, 3], d),
        "a_place_deg": _angle(M[:3, :3] @ axis, G[:3, :3] @ axis),
        "taught_mm": _lateral(H[:3, 3] - M[:3, 3], d),
        "taught_deg": _angle(H[:3, :3] @ axis, M[:3, :3] @ axis),
    }
    return {k: round(v, 3) for k, v in out.items()}


def _split_note(split: dict[str, float] | None) -> str:
    if split is None:
        return ""
    return (
        f"; as the insertion began the part was {split['total_mm']:.2f} mm / {split['total_deg']:.2f} deg off its "
        f"seat's axis (grasp {split['grasp_mm']:.2f} mm / {split['grasp_deg']:.2f} deg, A's placement "
        f"{split['a_place_mm']:.2f} mm / {split['a_place_deg']:.2f} deg, taught pose {split['taught_mm']:.2f} mm / "
        f"{split['taught_deg']:.2f} deg)"
    )


def jam_note(ev: dict[str, Any]) -> str:
    """What a guarded insertion that stopped short did, from its trace event: depth of length, the largest
    contact force, when, the sideways corrections tried and how far the other part was pushed."""
    ins = ev["insertion"]
    force = f", contact force {ins['max_force_n']:.0f} N" if ins.get("max_force_n") is not None else ""
    other = ""
    if ins.get("other_moved_mm", 0.0) > 0.5 and ev.get("other"):
        other = f"; {ev['other']} was pushed {ins['other_moved_mm']:.1f} mm"
    return (
        f"{ev['part']} jammed at {ins['depth_mm']:.1f} of {ins['length_mm']:.1f} mm depth{force} in "
        f"{ev['label']!r} at {_t(ev)} (met resistance {ins['tries']} times; sideways corrections up to "
        f"{float(np.linalg.norm(ins['correction_mm'])):.2f} mm did not free it: {ins['reason']}{other}"
        f"{_same_depth_note(ins)}{_realigned_note(ins)})"
    )


def knocked_before(events: Sequence[dict[str, Any]], jam: dict[str, Any]) -> dict[str, Any] | None:
    """The first event, in trace order before ``jam``, in which another motion toppled the part ``jam`` went
    into (``jam["other"]``; any free part when it is not named) or moved it more than :data:`KNOCKED_MM`;
    None when nothing did."""
    for ev in events:
        if ev is jam:
            return None
        if "pushed_mm" not in ev or ev.get("label") == jam.get("label"):
            continue
        if jam.get("other") not in (None, ev.get("part")):
            continue
        if ev.get("toppled") or ev["pushed_mm"] > KNOCKED_MM:
            return ev
    return None


def jam_story(events: Sequence[dict[str, Any]], jam: dict[str, Any]) -> tuple[str, FailureCause, dict[str, Any] | None]:
    """``(what happened, its cause, the knocking event or None)`` for the guarded insertion ``jam`` that stopped
    short: when a motion before it knocked the part it went into (:func:`knocked_before`), that comes first and is
    the cause (a topple, or a part moved off its goal), and the jam is told as what followed; else the jam
    (:func:`jam_note`)."""
    upset = knocked_before(events, jam)
    if upset is None:
        return jam_note(jam), FailureCause.JAM, None
    holding = f" (holding {upset['holding']})" if upset.get("holding") else ""
    what = "toppled" if upset.get("toppled") else "was knocked"
    text = (
        f"{upset['part']} {what} at {_t(upset)} while {upset['by']!r}{holding} ran (moved "
        f"{upset['pushed_mm']:.1f} mm, tilted {upset['tilted_deg']:.0f} deg), before the insertion; then "
        f"{jam_note(jam)}"
    )
    return text, FailureCause.TOPPLE if upset.get("toppled") else FailureCause.OFF_GOAL, upset


def _same_depth_note(ins: dict[str, Any]) -> str:
    """Resistance met at the same depth however far the line was shifted sideways: the search moved the part
    but nothing it tried changed where it stopped (a rim it never crossed into, a tilt, a stop)."""
    span, shifted = ins.get("contact_depth_mm"), ins.get("max_offset_mm", 0.0)
    if not span or ins.get("tries", 0) < 4 or span[1] - span[0] > SAME_DEPTH_MM or shifted < 2.0 * SAME_DEPTH_MM:
        return ""
    return (
        f"; it met the resistance at {span[0]:.1f}-{span[1]:.1f} mm depth through every shift (up to {shifted:.1f} mm)"
    )


def _realigned_note(ins: dict[str, Any]) -> str:
    if not ins.get("realigned_mm") and not ins.get("realigned_deg"):
        return ""
    return (
        f"; the line was re-aimed {ins['realigned_mm']:.1f} mm / {ins['realigned_deg']:.1f} deg for the part as "
        "measured in the hand"
    )


def failure_story(report: RunReport, split: dict[str, float] | None) -> tuple[str, FailureCause, dict[str, Any]]:
    """``(what happened, its cause, the evidence)`` for an assembly outside tolerance, from the trace's events.

    In order: a guarded insertion that did not get in (:attr:`FailureCause.JAM`: depth of length, the
    contact force, when); a part that toppled (:attr:`FailureCause.TOPPLE`: which motion, when, how far it
    tilted); a free part pushed by a motion (:attr:`FailureCause.OFF_GOAL`: by which motion, how far, when);
    a part pushed in the hand (a jam when the motion was an insertion); a part that tilted or dropped as it
    was let go; else the insertion's error split (:func:`insertion_error`), or that no event explains it.
    The evidence is the event itself plus ``split`` (JSON-ready, for ``report.json``'s ``failure_details``).
    """
    events = _events(report)
    evidence: dict[str, Any] = {"insertion_error": split} if split is not None else {}
    note = _split_note(split)
    jams = [e for e in events if "insertion" in e and not e["insertion"].get("inserted", True)]
    if jams:
        text, cause, upset = jam_story(events, jams[-1])
        if upset is not None:
            evidence["knocked"] = upset
        return text + note, cause, {"event": _public(jams[-1]), **evidence}
    toppled = [e for e in events if e.get("toppled")]
    if toppled:
        ev = max(toppled, key=lambda e: e["tilted_deg"])
        text = (
            f"{ev['part']} toppled at {_t(ev)} while {ev['by']!r} ran (tilted {ev['tilted_deg']:.0f} deg, "
            f"moved {ev['pushed_mm']:.1f} mm)"
        )
        return text + note, FailureCause.TOPPLE, {"event": ev, **evidence}
    pushed = [e for e in events if "pushed_mm" in e]
    if pushed:
        ev = max(pushed, key=lambda e: e["pushed_mm"])
        holding = f" (holding {ev['holding']})" if ev.get("holding") else ""
        text = f"{ev['part']} moved {ev['pushed_mm']:.1f} mm during {ev['by']!r}{holding} at {_t(ev)}"
        return text + note, FailureCause.OFF_GOAL, {"event": ev, **evidence}
    slip = _worst_slip(report)
    if slip is not None:
        text = (
            f"{slip.get('part', 'the part')} was pushed {slip['slip_in_hand_mm']:.1f} mm in the hand by "
            f"{slip.get('after') or slip['label']!r} before {_t(slip)} (it met resistance there)"
        )
        cause = FailureCause.JAM if slip.get("after_kind") == "insertion" else FailureCause.OFF_GOAL
        return text + note, cause, {"event": slip, **evidence}
    released = [
        e
        for e in events
        if "dropped_mm" in e and (e.get("tilted_deg", 0.0) > RELEASE_TILT_DEG or e["dropped_mm"] > RELEASE_DROP_MM)
    ]
    if released:
        ev = max(released, key=lambda e: e.get("tilted_deg", 0.0))
        text = (
            f"{ev['part']} tilted {ev.get('tilted_deg', 0.0):.1f} deg and dropped {ev.get('dropped_mm', 0.0):.1f} mm "
            f"as {ev['label']!r} let it go at {_t(ev)}"
        )
        return text + note, FailureCause.OFF_GOAL, {"event": ev, **evidence}
    if split is not None:
        return note.removeprefix("; "), FailureCause.OFF_GOAL, evidence
    return "no execution event explains it (nothing pushed, toppled or jammed)", FailureCause.OFF_GOAL, evidence


def _public(ev: dict[str, Any]) -> dict[str, Any]:
    """An insertion event without its poses (they are in the execute stage's trace)."""
    return {k: v for k, v in ev.items() if not k.startswith("T_")}
