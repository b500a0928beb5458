"""Torque-guided turns of a guarded insertion: the hand yields to the contact's moment, as a compliant wrist does.

A part held a degree or two off the axis of a long guide (a dovetail slider in its groove, a T-slider in its
slot: a few tenths of a millimetre of play over 40-80 mm) meets the guide's mouth with a corner or an edge and
stops however far the line is shifted sideways. A real cell turns it into line with the guide itself: a remote
centre compliance lets the wrist rotate about a point near the part's leading end, or the controller rotates the
hand to null the torque its wrist force/torque sensor reads. :class:`TorqueTurn` is that controller, one
admittance step per resistance: ``dtheta = K * tau`` (radians per newton-metre), bounded per step and in all, the
gain halved each time the torque turns back (the part crossed the guide's line).

Only what a wrist F/T sensor and the joint encoders give drives it: the contact force and its moment
(:class:`~asmteach.core.arm.insertion_records.PartContact`'s ``force_world`` and ``torque_world``, moved to the
compliance centre) and the TCP pose from forward kinematics; the centre itself is a point of the part's model
where the plan believes it held (:func:`leading_point`), as a tool's compliance centre is configured.
Units: metres, newtons, newton-metres, radians (degrees where a name says so). Frames: world unless named.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from asmteach.core import geometry

__all__ = [
    "TorqueTurn",
    "TurnSettings",
    "TwistSearch",
    "TwistSettings",
    "giving_back",
    "leading_point",
    "torque_about",
    "turn_about",
]


@dataclass(frozen=True)
class TurnSettings:
    """The admittance of the torque-guided turn.

    ``gain_rad_per_nm``: turn per newton-metre of contact torque about the compliance centre; ``step_max_deg``
    and ``total_max_deg``: the most one turn and all turns together rotate the hand; ``min_torque_nm``: a smaller
    torque says nothing (a part pressing square on a stop); ``max_turns``: turns before only the sideways
    search goes on; ``after_shifts``: turns begin once this many sideways shifts met resistance (the search
    had its chance at a lateral miss); ``enabled``: False runs the guarded insertion without turns (as before
    Session 16); ``give_back``: once the part is home, the hand turns back toward the planned orientation a
    step at a time while the guide lets it (:func:`giving_back`): turns that kept it in the hand left
    gen_dovetail_slide_s0_1 seed 9's slider home but 3.1 deg off in its groove.
    """

    gain_rad_per_nm: float = 0.15
    step_max_deg: float = 0.5
    total_max_deg: float = 3.0
    min_torque_nm: float = 0.02
    max_turns: int = 10
    after_shifts: int = 5
    enabled: bool = True
    give_back: bool = True


def torque_about(
    force_world: np.ndarray | None, torque_world: np.ndarray | None, point: np.ndarray
) -> np.ndarray | None:
    """The moment (N m, world) about ``point`` (world, metres) of a wrench given as its force (N) and its moment
    about the world origin; None when either is unknown."""
    if force_world is None or torque_world is None:
        return None
    return np.asarray(torque_world, dtype=float) - np.cross(np.asarray(point, dtype=float), force_world)


def turn_about(R: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """The 4x4 world transform that rotates by ``R`` (3x3, world) about ``centre`` (world, metres)."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.asarray(centre, dtype=float) - R @ np.asarray(centre, dtype=float)
    return T


def giving_back(R: np.ndarray, step_max_deg: float) -> list[np.ndarray]:
    """The hand's total turns (3x3, world) that take the turn ``R`` back to none about the same axis, each at most
    ``step_max_deg`` from the one before; the last is the identity. Empty when ``R`` is no turn."""
    rotvec = Rotation.from_matrix(np.asarray(R, dtype=float)[:3, :3]).as_rotvec()
    angle = float(np.linalg.norm(rotvec))
    if angle < 1e-9:
        return []
    n = max(1, int(np.ceil(np.degrees(angle) / step_max_deg - 1e-9)))
    return [geometry.from_rotvec((1.0 - k / n) * rotvec)[:3, :3] for k in range(1, n + 1)]


def leading_point(vertices_tcp: np.ndarray, com_tcp: np.ndarray, direction_tcp: np.ndarray) -> np.ndarray:
    """The compliance centre (TCP frame, metres): the point of the line through the part's centre of mass
    ``com_tcp`` along the insertion ``direction_tcp`` (unit) level with the part's leading vertex (its most
    advanced one along the direction). Turning about it leaves the part's front where it is, as a remote
    centre compliance placed at a peg's tip does."""
    d = np.asarray(direction_tcp, dtype=float)
    d = d / np.linalg.norm(d)
    c = np.asarray(com_tcp, dtype=float)
    lead = float(np.max(np.asarray(vertices_tcp, dtype=float) @ d))
    return c + (lead - float(c @ d)) * d


class TorqueTurn:
    """The hand's turns from the contact torque read at each resistance (:class:`TurnSettings`).

    :meth:`next` takes the torque about the compliance centre and says whether to try a turn before any
    sideways shift; :meth:`unreached` takes back a turn the arm cannot make. ``R`` is the hand's total turn
    (3x3, world); ``steps_deg`` lists the turns standing.

    The guard turns only once :attr:`TurnSettings.after_shifts` sideways shifts met resistance: a front
    resting on the rim beside the mouth (a lateral miss) feels a torque that can turn it the wrong way
    (turning at the first resistance, gen_t_slot_slide_s0_0 seed 8, in after one shift without turns, jammed
    at 23.6 of 50 mm 2.7 deg turned), and the search frees a lateral miss within a few shifts (the slow
    real-peg test: 4). Waiting for shifts at one depth does not tell the two apart: a miss on a flat rim
    stops at one depth too, and a wedged slider creeps deeper with each shift.
    Turns are not judged by the depth each gains: a turn series taken back when the part got no deeper lost
    gen_dovetail_slide_s0_3 seed 7, whose first turns gain nothing until the later ones free it.
    """

    def __init__(self, settings: TurnSettings | None = None) -> None:
        self.s = settings or TurnSettings()
        self.R = np.eye(3)
        self.gain = self.s.gain_rad_per_nm
        self.prev: np.ndarray | None = None
        self.steps_deg: list[float] = []
        self.last_torque_nm = 0.0
        self.step_max = np.radians(self.s.step_max_deg)
        self.tried = 0  # turns made, kept or not
        self.unreachable = 0  # turns the arm could not make (no IK)
        self._R_before = np.eye(3)

    @property
    def total_deg(self) -> float:
        """The hand's total turn so far (degrees)."""
        return float(np.degrees(geometry.rotation_angle(self.R)))

    def next(self, torque: np.ndarray | None) -> bool:
        """After a resistance with contact ``torque`` (N m, world, about the compliance centre): True when
        :attr:`R` holds a new turn to try, else False."""
        R = self._step(torque)
        if R is None:
            return False
        self._R_before, self.R = self.R, R
        self.steps_deg.append(float(np.degrees(geometry.rotation_angle(R @ self._R_before.T))))
        self.tried += 1
        return True

    def _step(self, torque: np.ndarray | None) -> np.ndarray | None:
        """The total turn after one admittance step for ``torque``, or None when none can be made."""
        if torque is None or not self.s.enabled or self.tried >= self.s.max_turns:
            return None
        tau = np.asarray(torque, dtype=float)
        n = float(np.linalg.norm(tau))
        self.last_torque_nm = n
        if n < self.s.min_torque_nm:
            return None
        if self.prev is not None and float(tau @ self.prev) < 0.0:
            self.gain *= 0.5  # turned past the guide's line: the way in lies between the last two turns
        self.prev = tau
        angle = min(self.gain * n, self.step_max)
        R = geometry.from_rotvec(angle * tau / n)[:3, :3] @ self.R
        return R if geometry.rotation_angle(R) <= np.radians(self.s.total_max_deg) + 1e-9 else None

    def unreached(self) -> np.ndarray:
        """Take the last turn back because the arm could not make it (no IK) and halve the turns after it; the
        total turn (3x3, world) to go on with."""
        self.R = self._R_before
        self.steps_deg.pop()
        self.unreachable += 1
        self.step_max *= 0.5
        return self.R

    def note(self) -> str:
        """What the turns did, for a jam's reason."""
        if not self.s.enabled:
            return ""
        extra = f", {self.unreachable} out of the arm's reach" if self.unreachable else ""
        if not self.steps_deg:
            return f"; no turn kept (contact torque {self.last_torque_nm:.3f} N m{extra})"
        steps = ", ".join(f"{a:.2f}" for a in self.steps_deg)
        return f"; turned {len(self.steps_deg)} times ({steps} deg), {self.total_deg:.2f} deg in all{extra}"


@dataclass(frozen=True)
class TwistSettings:
    """The twist search about the insertion line, tried once the sideways shifts and the torque's turns are spent.

    A part rolled about the line itself (a T-slider's wide flange 2 deg off its slot's, with 0.85 mm of play over
    31 mm: 1.6 deg at most) rests a corner on the mouth's edge: the contact pushes straight back, so its moment
    has no part about the line and :class:`TorqueTurn` never rolls it, and no sideways shift frees it. A
    cell's force-controlled insertion then searches in rotation about the insertion axis as it does sideways:
    ``step_deg``, ``-step_deg``, ``2 step_deg``, ... up to ``max_deg`` either way about the line, each advanced
    until it meets resistance, then shifted sideways ``shifts`` times as the push says (the roll out of it, the
    front's edge may still sit on the mouth's: a T-slider's flange rests flush with the slot's floor); one that
    takes the part ``gain_m`` (metres) deeper than where it stuck is kept and the search goes on from there as
    before. ``enabled``: False gives up where the shifts do.
    """

    step_deg: float = 0.5
    max_deg: float = 3.0
    gain_m: float = 0.002
    shifts: int = 3
    enabled: bool = True


class TwistSearch:
    """The twists about the insertion line to try (:class:`TwistSettings`): angles alternating in sense and
    growing by a step, in degrees, from the untwisted line; :meth:`rotation` gives one as a 3x3 world turn
    about the line's direction."""

    def __init__(self, settings: TwistSettings | None = None) -> None:
        self.s = settings or TwistSettings()
        n = int(np.floor(self.s.max_deg / self.s.step_deg + 1e-9)) if self.s.step_deg > 0 else 0
        self.angles_deg = [sign * k * self.s.step_deg for k in range(1, n + 1) for sign in (1.0, -1.0)]
        self.tried: list[float] = []
        self.kept_deg = 0.0

    @property
    def left(self) -> bool:
        """Whether a twist remains to try."""
        return self.s.enabled and len(self.tried) < len(self.angles_deg)

    def next(self) -> float | None:
        """The next twist (degrees), or None when every one was tried (or the search is disabled)."""
        if not self.left:
            return None
        angle = self.angles_deg[len(self.tried)]
        self.tried.append(angle)
        return angle

    @staticmethod
    def rotation(angle_deg: float, direction: np.ndarray) -> np.ndarray:
        """The 3x3 world turn by ``angle_deg`` about the unit ``direction`` (the insertion line's)."""
        d = np.asarray(direction, dtype=float)
        return geometry.from_rotvec(np.radians(angle_deg) * d / np.linalg.norm(d))[:3, :3]

    def note(self) -> str:
        """What the twists did, for a jam's reason."""
        if not self.tried:
            return ""
        if self.kept_deg:
            return f"; twisted {self.kept_deg:+.1f} deg about the line"
        return f"; twisted about the line up to {max(abs(a) for a in self.tried):.1f} deg either way: no way in"
