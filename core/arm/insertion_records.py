"""What a guarded insertion is told and what it reports: its settings, the contact a world senses between two
parts, each resistance met and the outcome (:mod:`asmteach.core.arm.insertion` runs it).

Frames: world; metres, newtons, seconds inside; the ``as_dict`` records are in millimetres (the execution
trace's unit).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from asmteach.core import geometry
from asmteach.core.arm.compliance import TurnSettings, TwistSettings

__all__ = ["ContactSensing", "InsertionContact", "InsertionOutcome", "InsertionSettings", "PartContact"]


@dataclass(frozen=True)
class PartContact:
    """The contact between two parts: total normal force (N) and its force-weighted point (world, metres),
    with the first part's centre of mass (world, metres) to say on which side of it the contact acts, and the
    total force on the first part (``force_world``, world, newtons: each normal force along its normal; None
    when the world does not say) and its moment about the world origin (``torque_world``, N m; None when the world
    does not say): with the force, the wrench a wrist F/T sensor reads, about any point."""

    force_n: float
    point_world: np.ndarray | None
    com_world: np.ndarray
    force_world: np.ndarray | None = None
    torque_world: np.ndarray | None = None


@runtime_checkable
class ContactSensing(Protocol):
    """A world that reports the contact between two of its parts (a simulator; a cell with a wrist F/T sensor
    and a model of the parts could estimate it)."""

    def part_contact(self, part: str, other: str) -> PartContact: ...


@dataclass(frozen=True)
class InsertionSettings:
    """How the guarded insertion moves and what it calls resistance.

    ``step_m``: TCP travel between two readings; ``speed_m_s``: TCP speed along the line (None: the planned
    trajectory's mean speed); ``slip_limit_m``
    and ``force_limit_n``: resistance (slip of the part in the hand since the start, contact force between the
    parts); ``seated_m``: resistance this close to the planned end is the part seated; ``backoff_m``: how far
    it backs out before a sideways correction; ``search_step_m`` and ``search_radius_m``: size of one sideways
    correction and the farthest it shifts the line; ``max_tries``: corrections before it gives up (a jam);
    ``other_moved_m``: the other part pushed this far is resistance; ``turn``: the torque-guided turns tried at
    each resistance before a sideways shift; ``twist``: the search about the line once shifts and turns are
    spent (:mod:`asmteach.core.arm.compliance`).
    """

    step_m: float = 0.0005
    speed_m_s: float | None = None
    slip_limit_m: float = 0.0004
    force_limit_n: float = 20.0
    seated_m: float = 0.0015
    backoff_m: float = 0.0015
    search_step_m: float = 0.0004
    search_radius_m: float = 0.0025
    max_tries: int = 16
    other_moved_m: float = 0.0005
    turn: TurnSettings = field(default_factory=TurnSettings)
    twist: TwistSettings = field(default_factory=TwistSettings)


@dataclass
class InsertionContact:
    """One time the insertion met resistance: at ``depth_m`` of the planned length (how far the part itself
    went), with ``force_n`` (contact force, NaN if the world senses none) and ``slip_m`` (the part pushed in
    the hand), ``t_s`` seconds into the insertion, while the line was shifted by ``offset_m`` sideways."""

    depth_m: float
    force_n: float
    slip_m: float
    t_s: float
    offset_m: float

    def as_dict(self) -> dict[str, float]:
        return {
            "depth_mm": round(1000.0 * self.depth_m, 2),
            "force_n": round(self.force_n, 1) if np.isfinite(self.force_n) else None,  # type: ignore[dict-item]
            "slip_mm": round(1000.0 * self.slip_m, 2),
            "t_s": round(self.t_s, 3),
            "offset_mm": round(1000.0 * self.offset_m, 2),
        }


@dataclass
class InsertionOutcome:
    """What a guarded insertion did: ``inserted`` (reached the planned depth, or seated within ``seated_m``),
    the part's ``depth_m`` of ``length_m``, the sideways ``correction_m`` (world vector) it went in with, every
    resistance met (``contacts``), the robot ``seconds`` it took, and the other part's largest displacement
    ``other_moved_m`` with the time it first moved more than :attr:`InsertionSettings.other_moved_m`."""

    inserted: bool
    depth_m: float
    length_m: float
    correction_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    contacts: list[InsertionContact] = field(default_factory=list)
    seconds: float = 0.0
    other_moved_m: float = 0.0
    other_moved_t_s: float | None = None
    reason: str = ""
    realigned_mm: float = 0.0
    realigned_deg: float = 0.0
    """How far (mm, deg) the line's end TCP was re-aimed for the part's measured pose in the hand (0: as planned)."""
    turns_deg: list[float] = field(default_factory=list)
    T_turn: np.ndarray = field(default_factory=lambda: np.eye(4))
    """The torque-guided turns (degrees each) and the world transform they applied to the line's TCP poses."""
    given_back_deg: float = 0.0
    """How much of the turns the hand took back once the part was home (degrees; :attr:`TurnSettings.give_back`)."""
    twist_deg: float = 0.0
    """The twist about the insertion line the part went in with (degrees, signed about the line's direction; 0:
    none was needed; :class:`~asmteach.core.arm.compliance.TwistSearch`)."""

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready, in millimetres (the execution trace's unit)."""
        worst = max((c.force_n for c in self.contacts if np.isfinite(c.force_n)), default=None)
        return {
            "inserted": self.inserted,
            "depth_mm": round(1000.0 * self.depth_m, 2),
            "length_mm": round(1000.0 * self.length_m, 2),
            "correction_mm": np.round(1000.0 * self.correction_m, 2).tolist(),
            "tries": len(self.contacts),
            "contact_depth_mm": [
                round(1000.0 * min(c.depth_m for c in self.contacts), 2),
                round(1000.0 * max(c.depth_m for c in self.contacts), 2),
            ]
            if self.contacts
            else None,
            "max_offset_mm": round(1000.0 * max((c.offset_m for c in self.contacts), default=0.0), 2),
            "max_force_n": None if worst is None else round(worst, 1),
            "contacts": [c.as_dict() for c in self.contacts[:8]],
            "seconds": round(self.seconds, 3),
            "other_moved_mm": round(1000.0 * self.other_moved_m, 2),
            "other_moved_t_s": None if self.other_moved_t_s is None else round(self.other_moved_t_s, 3),
            "realigned_mm": round(self.realigned_mm, 2),
            "realigned_deg": round(self.realigned_deg, 2),
            "turns_deg": [round(a, 2) for a in self.turns_deg],
            "turned_deg": round(float(np.degrees(geometry.rotation_angle(self.T_turn[:3, :3]))), 2),
            "given_back_deg": round(self.given_back_deg, 2),
            "twist_deg": round(self.twist_deg, 2),
            "reason": self.reason,
        }
