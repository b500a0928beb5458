"""Guarded insertion: a held part goes along its insertion line in small steps, watching for resistance.

A planned insertion is a straight TCP line. Run blind, a part that meets the rim of its hole (a lateral
error larger than the clearance) is shoved on by the arm's position servos: it is pushed in the hand,
tilted, the other part is dragged along, and the assembly ends far off (the structures sweep's jams). A
real cell inserts force-guided instead; :func:`guarded_insert` does the same on any
:class:`~asmteach.core.robot.World`:

- the TCP advances ``step_m`` at a time along the planned line (any direction: down, sideways, up);
- after each step it reads the resistance: the part's slip in the hand since the insertion started (the
  hand's compliance acting as a force sensor; :meth:`~asmteach.core.robot.World.part_pose` is enough) and,
  on a world that senses contacts (:class:`ContactSensing`), the contact force between the two parts and
  where it acts;
- on resistance short of the planned depth it backs off and shifts the line sideways (perpendicular to
  the insertion): along the contact's lateral push, halving the step when the push turns back, the other
  sense when one reaches the search radius (:class:`~asmteach.core.arm.insertion_search.PushSearch`: a peg
  on a hole's rim and a cap on a post's top are pushed opposite ways), else along a spiral of growing
  radius, as a cell's search insertion does; it
  never pushes past ``force_limit_n`` or ``slip_limit_m``;
- still resisted after the search's first shifts (a tilt, not a lateral miss), it turns the hand with the
  contact torque about the part's leading end before each shift, as a compliant wrist yields
  (:class:`~asmteach.core.arm.compliance.TorqueTurn`, bounded per turn and in all);
- still resisted once the shifts and turns are spent, it twists the hand about the line itself, a little more
  each time, one sense then the other (:class:`~asmteach.core.arm.compliance.TwistSearch`): a part rolled
  about the line (a T-slider's flange) meets the mouth with a corner whose straight-back push has no moment
  about the line to turn it by;
- it watches the other part: how far it moved while the part came in, and when; the other part pushed more
  than ``other_moved_m`` since the last correction is resistance too (a light part slides on the table
  before any force builds up);
- given ``line_end`` (the TCP pose that puts the part, as it is measured in the hand, where the plan meant
  it: :func:`realigned_line_end`), the same line is run re-aimed: it first turns and shifts the hand to the
  re-aimed start, then goes in along the planned direction. A part held off the pose the plan assumed (a
  detection 16 deg off, side_pin s0_0 seed 7) otherwise meets the rim at a tilt no sideways search frees.

Units: metres, newtons, seconds (the robot's clock: the executed trajectories' own seconds). Frames: world.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from asmteach.core import geometry
from asmteach.core.arm.compliance import (
    TorqueTurn,
    TwistSearch,
    giving_back,
    torque_about,
    turn_about,
)
from asmteach.core.arm.insertion_records import (
    ContactSensing,
    InsertionContact,
    InsertionOutcome,
    InsertionSettings,
    PartContact,
)
from asmteach.core.arm.insertion_search import PushSearch, perpendicular, spiral
from asmteach.core.models import Trajectory

__all__ = ["SIDEWAYS_SHARE", "guarded_insert", "realigned_line_end"]


SIDEWAYS_SHARE = 0.1
"""A contact force whose component across the insertion line is at least this share of the contact's normal
force pushes the part that way (a rim's edge, a chamfer, a cap's mouth on a post's edge): the guard shifts the
line along it, as a compliant wrist would yield; a smaller share says nothing, and the side of the part the
contact acts on is read instead."""


class _Guard:
    """Moves the TCP along (possibly shifted) insertion lines and reads the resistance after every step."""

    def __init__(
        self,
        robot: Any,
        traj: Trajectory,
        part: str,
        other: str | None,
        s: InsertionSettings,
        line_end: np.ndarray | None = None,
        centre_tcp: np.ndarray | None = None,
    ) -> None:
        self.robot, self.arm, self.part, self.other, self.s = robot, traj.arm, part, other, s
        pos = np.asarray(traj.positions, dtype=float)
        self.T_start = robot.fk(self.arm, pos[0])
        self.T_end = robot.fk(self.arm, pos[-1])
        delta = self.T_end[:3, 3] - self.T_start[:3, 3]
        self.length = float(np.linalg.norm(delta))
        self.d = delta / self.length if self.length > 1e-9 else np.array([0.0, 0.0, -1.0])
        if line_end is not None:  # the same line (direction, length), re-aimed to end at line_end
            self.T_end = np.asarray(line_end, dtype=float).copy()
            self.T_start = self.T_end.copy()
            self.T_start[:3, 3] = self.T_end[:3, 3] - self.length * self.d
        self.u, self.w = perpendicular(self.d)
        self.centre_tcp = np.zeros(3) if centre_tcp is None else np.asarray(centre_tcp, dtype=float)
        self.R_turn = np.eye(3)  # the torque-guided turn of the hand about the compliance centre (world)
        self.contact: PartContact | None = None
        T_tcp = robot.fk(self.arm, robot.current(self.arm))
        self.T_tcp_part = geometry.invert(T_tcp) @ robot.part_pose(part)  # the part in the hand now
        self.T_other0 = robot.part_pose(other) if other else None
        self.T_other_ref = self.T_other0  # the other part since the last correction: pushed from here is resistance
        self.other_push = 0.0
        self.seconds = 0.0
        self.other_moved, self.other_moved_t = 0.0, None
        seconds = float(traj.times[-1] - traj.times[0])
        planned = self.length / seconds if seconds > 1e-9 else 0.02
        self.speed = s.speed_m_s if s.speed_m_s is not None else min(max(planned, 0.005), 0.1)
        self.names = robot.joint_names(self.arm)
        self.v_max = np.asarray(robot.speed_limits(self.arm), dtype=float)

    def pose_at(self, s: float, offset: np.ndarray) -> np.ndarray:
        """The TCP pose ``s`` metres along the line shifted sideways by ``offset`` (planned end's orientation),
        turned by ``R_turn`` about the compliance centre."""
        T = self.T_end.copy()
        T[:3, 3] = self.T_start[:3, 3] + s * self.d + offset
        return self.turn(T) @ T

    def turn(self, T: np.ndarray) -> np.ndarray:
        """The world transform of the hand's turn for the unturned TCP pose ``T``: ``R_turn`` about the centre."""
        return turn_about(self.R_turn, T[:3, :3] @ self.centre_tcp + T[:3, 3])

    def torque(self) -> np.ndarray | None:
        """The last reading's contact torque about the compliance centre where the encoders put it (N m, world)."""
        if self.contact is None:
            return None
        T_tcp = self.robot.fk(self.arm, self.robot.current(self.arm))
        centre = T_tcp[:3, :3] @ self.centre_tcp + T_tcp[:3, 3]
        return torque_about(self.contact.force_world, self.contact.torque_world, centre)

    def move_to(self, T: np.ndarray) -> bool:
        """One short step of the TCP to ``T`` (False when IK fails there)."""
        q0 = self.robot.current(self.arm)
        ik = self.robot.ik(self.arm, T, q0)
        if not ik.success or ik.q is None:
            return False
        dist = float(np.linalg.norm(self.robot.fk(self.arm, q0)[:3, 3] - T[:3, 3]))
        dt = max(dist / self.speed, 1.2 * float(np.max(np.abs(ik.q - q0) / self.v_max)), 0.01)
        self.robot.execute(
            Trajectory(arm=self.arm, joint_names=self.names, times=[0.0, dt], positions=np.vstack([q0, ik.q]))
        )
        self.seconds += dt
        self._watch_other()
        return True

    def _watch_other(self) -> None:
        if self.T_other0 is None or self.other is None:
            return
        T = self.robot.part_pose(self.other)
        moved = geometry.translation_distance(T, self.T_other0)
        if moved > self.other_moved:
            self.other_moved = moved
        if self.other_moved_t is None and moved > self.s.other_moved_m:
            self.other_moved_t = self.seconds
        self.other_push = geometry.translation_distance(T, self.T_other_ref)

    def settle_other(self) -> None:
        """Where the other part stands now is where it should stay (after a correction)."""
        if self.other is not None:
            self.T_other_ref = self.robot.part_pose(self.other)
        self.other_push = 0.0

    def reading(self, s: float, offset: np.ndarray) -> tuple[float, float, float, np.ndarray | None]:
        """``(slip_m, force_n, depth_m, lateral push direction or None)`` after a step to ``s``."""
        T_tcp = self.robot.fk(self.arm, self.robot.current(self.arm))
        T_part = self.robot.part_pose(self.part)
        expected = T_tcp @ self.T_tcp_part
        slip = geometry.translation_distance(T_part, expected)
        axial_lag = float(np.dot(expected[:3, 3] - T_part[:3, 3], self.d))
        depth = s - max(axial_lag, 0.0)
        force, away = float("nan"), None
        if self.other is not None and isinstance(self.robot, ContactSensing):
            c = self.robot.part_contact(self.part, self.other)
            force, self.contact = c.force_n, c
            if c.force_world is not None and c.force_n > 0.0:
                push = c.force_world - np.dot(c.force_world, self.d) * self.d
                n = float(np.linalg.norm(push))
                away = push / n if n >= SIDEWAYS_SHARE * c.force_n else None
            if away is None and c.point_world is not None:
                lateral = c.point_world - c.com_world
                lateral -= np.dot(lateral, self.d) * self.d
                n = float(np.linalg.norm(lateral))
                away = -lateral / n if n > 1e-5 else None
        if away is None and slip > 0.5 * self.s.slip_limit_m:
            # no contact sensing: the part is pushed sideways away from what it presses on
            lateral = (T_part[:3, 3] - expected[:3, 3]) - np.dot(T_part[:3, 3] - expected[:3, 3], self.d) * self.d
            n = float(np.linalg.norm(lateral))
            away = lateral / n if n > 1e-5 else None
        return slip, force, depth, away

    def resisted(self, slip: float, force: float) -> bool:
        """Too much slip in the hand, too much contact force, or the other part pushed along (a part that
        slides freely on the table resists little: its moving is the only sign)."""
        return (
            slip > self.s.slip_limit_m
            or (np.isfinite(force) and force > self.s.force_limit_n)
            or self.other_push > self.s.other_moved_m
        )


def _twist(
    g: _Guard, pos: float, slip: float, offset: np.ndarray, R_turns: np.ndarray, R_twist: np.ndarray
) -> tuple[float, np.ndarray]:
    """Back off from a resistance at ``pos`` (``slip`` the part's in the hand), then turn the hand to the twist
    ``R_twist`` about the line (3x3, world) after the turns ``R_turns``, shifted by ``offset``:
    ``(where along the line it stands now, the twist it holds)``; with no IK for the twist, the untwisted hand."""
    pos = max(0.0, pos - g.s.backoff_m - slip)
    g.move_to(g.pose_at(pos, offset))
    g.R_turn = R_turns @ R_twist
    if not g.move_to(g.pose_at(pos, offset)):
        R_twist = np.eye(3)
        g.R_turn = R_turns
    g.settle_other()
    return pos, R_twist


def _give_back(g: _Guard, pos: float, offset: np.ndarray) -> float:
    """The part home with the hand turned: turn the hand back toward the line's planned orientation about the
    compliance centre, a step at a time, as a compliant wrist lets the guide straighten the part once it is
    seated deep in it; a step the guide resists (the contact force over the limit, the part slipping in the
    hand or the other part pushed) is taken back and the rest kept. Degrees given back."""
    R0 = g.R_turn
    rotvec = Rotation.from_matrix(R0).as_rotvec()
    axis = rotvec / max(float(np.linalg.norm(rotvec)), 1e-12)
    slip0 = g.reading(pos, offset)[0]
    g.settle_other()
    for R in giving_back(R0, g.s.turn.step_max_deg):
        before, g.R_turn = g.R_turn, R
        if not g.move_to(g.pose_at(pos, offset)):
            g.R_turn = before
            break
        slip, force, _, _ = g.reading(pos, offset)
        tau = g.torque()
        if (
            slip - slip0 > g.s.slip_limit_m
            or (np.isfinite(force) and force > g.s.force_limit_n)
            or g.other_push > g.s.other_moved_m
            or (tau is not None and float(tau @ axis) > g.s.turn.min_torque_nm)
        ):
            g.R_turn = before
            g.move_to(g.pose_at(pos, offset))
            break
    return float(np.degrees(geometry.rotation_angle(R0 @ g.R_turn.T)))


def realigned_line_end(T_end: np.ndarray, T_tcp_part_planned: np.ndarray, T_tcp_part_held: np.ndarray) -> np.ndarray:
    """The TCP pose (world, metres) that puts the part held at ``T_tcp_part_held`` (measured in the hand) where
    the planned end ``T_end`` puts it as the plan assumed it held (``T_tcp_part_planned``): ``T_end @
    T_tcp_part_planned @ inv(T_tcp_part_held)``. Pass the planned pose as the symmetric equivalent nearest the
    held one (a symmetric part's detection may be any of them: turning the hand by a symmetry gains nothing)."""
    return (
        np.asarray(T_end, dtype=float) @ np.asarray(T_tcp_part_planned, dtype=float) @ geometry.invert(T_tcp_part_held)
    )


def guarded_insert(
    robot: Any,
    traj: Trajectory,
    part: str,
    other: str | None = None,
    settings: InsertionSettings | None = None,
    line_end: np.ndarray | None = None,
    centre_tcp: np.ndarray | None = None,
) -> InsertionOutcome:
    """Run the insertion ``traj`` (a straight TCP line holding ``part``) force-guided; see the module doc.

    ``robot`` is a :class:`~asmteach.core.robot.World` and :class:`~asmteach.core.interfaces.RobotModel`
    (``fk``, ``ik``, ``execute``, ``part_pose``, ``current``); ``other`` is the part inserted into (watched,
    and its contacts read when the world is :class:`ContactSensing`). The arm starts at the trajectory's start.
    ``line_end`` (``T_world_tcp``, from :func:`realigned_line_end`) re-aims the line: the arm first moves to
    its start (the planned direction and length back from ``line_end``); with no IK there, the planned line
    runs. ``centre_tcp`` (TCP frame, metres; default the TCP) is the compliance centre the hand turns about
    (:func:`~asmteach.core.arm.compliance.leading_point`). Returns the :class:`InsertionOutcome`; it never
    raises on a jam (the part stays where it stopped, eased back to the depth where the force stayed under the
    limit).
    """
    s = settings or InsertionSettings()
    g = _Guard(robot, traj, part, other, s, centre_tcp=centre_tcp)
    if line_end is not None:
        planned = robot.fk(traj.arm, np.asarray(traj.positions, dtype=float)[-1])
        aimed = _Guard(robot, traj, part, other, s, line_end, centre_tcp)
        if aimed.length >= 1e-6 and aimed.move_to(aimed.pose_at(0.0, np.zeros(3))):
            g = aimed
            g.settle_other()  # the turn may nudge the other part: resistance counts from here
            g.T_tcp_part = geometry.invert(robot.fk(g.arm, robot.current(g.arm))) @ robot.part_pose(part)
    out = InsertionOutcome(inserted=False, depth_m=0.0, length_m=g.length)
    if line_end is not None:
        out.realigned_mm = 1000.0 * geometry.translation_distance(g.T_end, planned)
        out.realigned_deg = float(np.degrees(geometry.rotation_distance(g.T_end, planned)))
    if g.length < 1e-6:
        robot.execute(traj)
        out.inserted = True
        return out
    offset = np.zeros(3)
    pos, best_depth, tries, spiral_k = 0.0, 0.0, 0, 0
    search = PushSearch(s.search_step_m, s.search_radius_m)
    turner = TorqueTurn(s.turn)
    twister, R_twist = TwistSearch(s.twist), np.eye(3)
    stuck_at: float | None = None  # while twists are tried: the depth the part stuck at before them
    twist_origin, twist_shifts = np.zeros(3), 0  # the offset each twist starts from, and the shifts it has left
    steps = max(1, int(np.ceil(g.length / s.step_m)))
    while True:
        target = min(g.length, pos + g.length / steps)
        if not g.move_to(g.pose_at(target, offset)):
            out.reason = "no IK on the insertion line"
            break
        pos = target
        slip, force, depth, away = g.reading(pos, offset)
        best_depth = max(best_depth, depth)
        resisted = g.resisted(slip, force)
        if not resisted and pos >= g.length - 1e-9:
            out.inserted = True
            break
        if not resisted:
            continue
        if depth >= g.length - s.seated_m:
            out.inserted = True  # it met the seat (a blind hole's bottom, a stop) where the plan ends
            break
        out.contacts.append(InsertionContact(depth, force, slip, g.seconds, float(np.linalg.norm(offset))))
        if stuck_at is not None and depth > stuck_at + s.twist.gain_m:
            # the twist took the part past where it stuck: keep it, and search from here as at the start
            stuck_at, twister.kept_deg = None, twister.tried[-1]
            tries, spiral_k = 0, 0
            search, turner = PushSearch(s.search_step_m, s.search_radius_m), TorqueTurn(s.turn)
        if stuck_at is not None:
            new = search.next(offset, away) if twist_shifts > 0 else None
            if new is not None and np.linalg.norm(new) <= s.search_radius_m:
                # a few shifts at each twist: the front's edge on the mouth's edge, once the roll is out of it
                twist_shifts -= 1
                pos, offset = max(0.0, pos - s.backoff_m - slip), new
                g.move_to(g.pose_at(pos, offset))
                g.settle_other()
                continue
            angle = twister.next()
            if angle is None:
                out.reason = f"still resisted after {s.max_tries} sideways corrections"
                break
            offset, search, twist_shifts = twist_origin, PushSearch(s.search_step_m, s.search_radius_m), s.twist.shifts
            pos, R_twist = _twist(g, pos, slip, offset, turner.R, TwistSearch.rotation(angle, g.d))
            continue
        # the sideways search first (a lateral miss); still resisted after its shifts: a tilt, turn from then on
        turn = turner.next(g.torque()) if len(out.contacts) > s.turn.after_shifts else False
        tries += not turn
        if tries > s.max_tries:
            angle = twister.next() if not twister.tried else None
            if angle is None:
                out.reason = f"still resisted after {s.max_tries} sideways corrections"
                break
            # shifts and turns spent: twist about the line from where the shifts began, the turns taken back
            # (they followed a straight-back push's moment, which says nothing about a roll)
            stuck_at = best_depth
            twist_origin = search.origin.copy() if search.origin is not None else offset.copy()
            offset, search, twist_shifts = twist_origin, PushSearch(s.search_step_m, s.search_radius_m), s.twist.shifts
            turner = TorqueTurn(s.turn)
            pos, R_twist = _twist(g, pos, slip, offset, turner.R, TwistSearch.rotation(angle, g.d))
            continue
        # back off (the hand's spring lets go of the part), then turn the hand or shift the line sideways
        pos = max(0.0, pos - s.backoff_m - slip)
        g.move_to(g.pose_at(pos, offset))
        g.R_turn = turner.R @ R_twist
        if turn:  # yield to the contact's torque, as a compliant wrist would, and advance again
            if turner.tried == 1 and search.origin is not None:
                offset = search.origin.copy()  # the shifts changed nothing: back to where they began
            if g.move_to(g.pose_at(pos, offset)):
                g.settle_other()
                continue
            g.R_turn = turner.unreached() @ R_twist  # no IK for the turned hand: this resistance goes to the search
            tries += 1
        new = search.next(offset, away)
        if new is None:
            spiral_k += 1
            new = spiral(spiral_k, s.search_step_m, g.u, g.w)
        if np.linalg.norm(new) > s.search_radius_m:
            spiral_k += 1
            new = spiral(spiral_k, s.search_step_m, g.u, g.w)
            if np.linalg.norm(new) > s.search_radius_m:
                out.reason = f"no way in within {1000.0 * s.search_radius_m:.1f} mm sideways"
                break
        offset = new
        if not g.move_to(g.pose_at(pos, offset)):
            out.reason = "no IK for the sideways correction"
            break
        g.settle_other()
    if out.inserted and stuck_at is not None:
        twister.kept_deg = twister.tried[-1]  # the twist tried last took the part home
    out.twist_deg = twister.kept_deg
    if out.inserted and (turner.steps_deg or twister.kept_deg) and s.turn.give_back:
        out.given_back_deg = _give_back(g, pos, offset)
    out.depth_m = best_depth if not out.inserted else max(best_depth, g.reading(pos, offset)[2])
    out.correction_m = offset
    out.turns_deg, out.T_turn = list(turner.steps_deg), g.turn(g.pose_at(g.length, offset))
    if not out.inserted:
        out.reason += turner.note() + twister.note()
    out.seconds = g.seconds
    out.other_moved_m, out.other_moved_t_s = g.other_moved, g.other_moved_t
    return out
