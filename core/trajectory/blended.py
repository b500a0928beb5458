"""Time-optimal, blended time parametrisation of a joint path with toppra.

The trapezoid of :mod:`.timing` stops the robot at every waypoint. Here a path
is parametrised once through all its waypoints under per-joint velocity
(rad/s) and acceleration (rad/s^2) limits by TOPP-RA (``toppra``), and stops
only where the caller asks (``stops``) and at its two ends.

**Which geometric path.** TOPP-RA needs a path ``q(s)`` with continuous
tangent; a polyline has corners where the path speed must drop to zero. A
cubic spline through the waypoints (``toppra.SplineInterpolator``) has no
corners but wanders away from the straight joint-space segments the motion
planner checked, by an amount nobody bounds (a third of a segment on a sharp
turn of a T-RRT path), so it would need a full collision re-check in the scene
of each motion. We keep the checked polyline instead and round each corner by
a circular arc in joint space (as Kunz and Stilman's time-optimal trajectory
generation, MoveIt's TOTG, does; :mod:`.blended_path`): the arc is tangent to both segments, takes
at most half of each, and its distance from the corner, which is its largest
distance from the polyline, is at most ``max_deviation`` radians (Euclidean
joint-space norm). So every configuration of the blended path lies within
``max_deviation`` of a configuration of the checked path, and nowhere else.
The default, ``DEFAULT_DEVIATION`` = 0.005 rad, is half the motion planners'
``collision_resolution`` (0.01 rad): the planners' discrete motion check
already trusts every configuration that lies within that distance of a
checked one (it checks the segment only every 0.01 rad), so a blend stays in
the band of configurations today's check vouches for. Dense paths (the
straight TCP lines, 4 mm steps) turn little at each waypoint and are rounded
almost entirely; a sharp T-RRT corner is cut by at most 0.005 rad and passed
slowly, not at rest.

**Re-check and fall-back.** When the caller has the scene of the motion it
passes ``is_valid`` (``(m, dof) -> (m,) bool``, True where free, the planner's
own check). Every arc is then sampled every ``check_step`` radians and checked;
an arc with an invalid sample is redone with half the deviation, twice, and
then dropped: the corner is kept sharp and the robot stops there (the
trapezoid's behaviour, on the checked segments). Lines are the checked
segments themselves and are not re-checked.

**Limits.** The accelerations of the path jump where a line meets an arc;
TOPP-RA enforces its constraints at grid points only, and the grid has a point
at every such junction and is dense along arcs. The result is then sampled
evenly (``rate_hz``; these samples are what the robot gets) and its
velocities and accelerations there and at every grid point are checked
against the limits; if any exceeds them, the limits given to TOPP-RA
are scaled down and it runs again. If TOPP-RA fails on a piece, or is no
faster there than the trapezoid (a lone straight move: its grid costs a few per
cent), that piece is timed with the trapezoid on the checked segments, so the
result is never slower than the old timing. Jerk is not limited (TOPP-RA is second order and the
robots here give no jerk limits).

**Path speed.** ``path_speed`` caps the joint-space path speed ``|dq/dt|``
(rad/s, Euclidean): for a straight TCP line with TCP metres per joint-space
radian ``k``, a TCP speed ``v`` is ``path_speed = v / k``. The insertion uses it
to keep a set speed along its line.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import toppra
import toppra.algorithm
import toppra.constraint

from asmteach.core.errors import UserError
from asmteach.core.trajectory.blended_path import MIN_TURN, BlendedPath
from asmteach.core.trajectory.timing import TimedPath, joint_limits, time_parametrize

__all__ = ["DEFAULT_DEVIATION", "BlendReport", "time_optimal"]

DEFAULT_DEVIATION = 0.005
"""Largest distance (rad, Euclidean joint-space norm) of a corner blend from the corner it rounds."""

_MAX_TURN = np.pi - 1e-3  # rad: a reversal cannot be rounded; the robot stops there

logging.getLogger("toppra").setLevel(logging.ERROR)  # toppra logs every failure at WARNING; we report them


@dataclass
class BlendReport:
    """What :func:`time_optimal` did: corners blended and stopped at, fall-backs, limit scale used."""

    blended: int = 0
    stops: int = 0
    narrowed: int = 0  # blends redone narrower after a failed collision re-check
    unblended: int = 0  # blends dropped (corner kept, robot stops there) after failed re-checks
    trapezoid_pieces: int = 0  # pieces toppra could not time, timed rest-to-rest instead
    limit_scale: float = 1.0


def _grid(path: BlendedPath, line_step: float, arc_turn: float) -> np.ndarray:
    """Grid points (rad of path): every junction, lines every ``line_step``, arcs every ``arc_turn`` rad of turn."""
    grid = [np.zeros(1)]
    for p in path.pieces():
        h = line_step if p.radius == 0.0 else min(line_step, arc_turn * p.radius)
        n = max(1, int(np.ceil(p.length / h)))
        grid.append(p.s0 + np.linspace(0.0, p.length, n + 1)[1:])
    g = np.concatenate(grid)
    g[-1] = path.path_interval[1]
    keep = np.concatenate([[True], np.diff(g) > 1e-12])
    g = g[keep]
    g[-1] = path.path_interval[1]
    return g


def _toppra(
    path: BlendedPath, vel: np.ndarray, acc: np.ndarray, path_speed: float | None, grid: np.ndarray
) -> toppra.ParametrizeConstAccel | None:
    constraints: list = [toppra.constraint.JointVelocityConstraint(vel)]
    if path_speed is not None:
        # |q'(s)| = 1 (arc length), so capping every joint at |q_j'(s)| * path_speed caps s_dot at path_speed.
        def vlim(s: float) -> np.ndarray:
            cap = np.maximum(np.minimum(vel, np.abs(path(s, 1)) * path_speed), 1e-12)
            return np.stack([-cap, cap], axis=1)

        constraints.append(toppra.constraint.JointVelocityConstraintVarying(vlim))
    constraints.append(
        toppra.constraint.JointAccelerationConstraint(
            acc, discretization_scheme=toppra.constraint.DiscretizationType.Interpolation
        )
    )
    algo = toppra.algorithm.TOPPRA(
        constraints, path, gridpoints=grid, solver_wrapper="seidel", parametrizer="ParametrizeConstAccel"
    )
    return algo.compute_trajectory(0.0, 0.0)


def _sample(traj: toppra.ParametrizeConstAccel, rate_hz: float) -> tuple[np.ndarray, ...]:
    """Times (s) evenly at ``rate_hz`` and positions, velocities, accelerations there."""
    duration = float(traj.duration)
    n = max(1, int(np.ceil(duration * rate_hz - 1e-9)))
    t = np.linspace(0.0, duration, n + 1)
    return t, traj(t, 0), traj(t, 1), traj(t, 2)


def _grid_kinematics(traj: toppra.ParametrizeConstAccel) -> tuple[np.ndarray, np.ndarray]:
    """Velocities and accelerations at every grid point's time, where the path acceleration switches.

    They are checked but not sent: a grid time a few microseconds from an even sample would make an interval
    whose finite differences only measure rounding.
    """
    t = np.asarray(traj._ts, float)  # the grid's times (toppra keeps them in this attribute)
    t = t[t <= float(traj.duration)]
    return traj(t, 1), traj(t, 2)


def _within(v: np.ndarray, a: np.ndarray, vel: np.ndarray, acc: np.ndarray) -> bool:
    return bool(np.all(np.abs(v) <= vel * (1 + 1e-6) + 1e-9) and np.all(np.abs(a) <= acc * (1 + 1e-6) + 1e-9))


def _time_piece(
    pts: np.ndarray,
    dev: np.ndarray,
    vel: np.ndarray,
    acc: np.ndarray,
    path_speed: float | None,
    rate_hz: float,
    report: BlendReport,
) -> TimedPath:
    """One rest-to-rest piece (no stop inside) through ``pts``, blended by ``dev``."""
    path = BlendedPath(pts, dev)
    if path.path_interval[1] <= 1e-9:
        return time_parametrize(pts, vel, acc, rate_hz=rate_hz)
    # At least 100 grid intervals (toppra's own default): a slow move's ramp from rest takes a whole interval.
    grid = _grid(path, line_step=min(0.02, path.path_interval[1] / 100.0), arc_turn=0.05)
    trapezoid = time_parametrize(pts, vel, acc, rate_hz=rate_hz)
    # 0.5 % below the limits first: between samples an arc's rotating tangent can take a joint's acceleration
    # up to ~0.1 % past its value at the samples (seen on the demo's plans with 1.0 here).
    for scale in (0.995, 0.97, 0.9, 0.8, 0.7):
        traj = _toppra(path, vel * scale, acc * scale, None if path_speed is None else path_speed * scale, grid)
        if traj is None:
            break
        if path_speed is None and traj.duration >= trapezoid.duration:
            # Nothing to gain (a lone straight move, or corners so sharp the blends are passed almost at rest;
            # toppra's grid then costs a few per cent): the trapezoid on the checked segments is as good.
            break
        t, q, v, a = _sample(traj, rate_hz)
        if _within(v, a, vel, acc) and _within(*_grid_kinematics(traj), vel, acc):
            report.blended += len(path.arcs)
            report.limit_scale = min(report.limit_scale, scale)
            q[0], q[-1] = pts[0], pts[-1]
            v[0] = v[-1] = 0.0
            nearest = [int(np.argmin(np.linalg.norm(q - w, axis=1))) for w in pts]
            nearest[0], nearest[-1] = 0, len(t) - 1
            return TimedPath(
                times=t,
                positions=q,
                velocities=v,
                accelerations=a,
                waypoint_index=np.maximum.accumulate(np.array(nearest, dtype=int)),
            )
    # toppra failed, kept exceeding the limits or was no faster: rest-to-rest on the checked segments
    report.trapezoid_pieces += 1
    report.stops += len(pts) - 2
    return trapezoid


def _concat(parts: Sequence[TimedPath]) -> TimedPath:
    times, pos, vel, acc, idx = [], [], [], [], []
    t0, count = 0.0, 0
    for k, p in enumerate(parts):
        skip = 0 if k == 0 else 1  # the first sample of a piece is the last of the one before
        times.append(p.times[skip:] + t0)
        pos.append(p.positions[skip:])
        vel.append(p.velocities[skip:])
        acc.append(p.accelerations[skip:])
        wi = p.waypoint_index + count - skip
        idx.append(wi if k == 0 else wi[1:])
        t0 += p.duration
        count += len(p.times) - skip
    return TimedPath(
        times=np.concatenate(times),
        positions=np.vstack(pos),
        velocities=np.vstack(vel),
        accelerations=np.vstack(acc),
        waypoint_index=np.concatenate(idx),
    )


def time_optimal(
    path: np.ndarray,
    v_max: float | np.ndarray,
    a_max: float | np.ndarray,
    *,
    max_deviation: float = DEFAULT_DEVIATION,
    stops: Sequence[int] = (),
    path_speed: float | None = None,
    is_valid: Callable[[np.ndarray], np.ndarray] | None = None,
    check_step: float = 0.01,
    rate_hz: float = 100.0,
    report: BlendReport | None = None,
) -> TimedPath:
    """Time-optimal, blended parametrisation of ``path`` ``(n, dof)`` (radians); see the module docstring.

    ``v_max`` (rad/s) and ``a_max`` (rad/s^2) are scalars or ``(dof,)``.
    The robot is at rest at the first and last waypoints and at every waypoint
    index in ``stops``; it passes every other waypoint within
    ``max_deviation`` rad. ``path_speed`` (rad/s) caps the joint-space path
    speed. ``is_valid`` re-checks the blends (sampled every ``check_step`` rad)
    and narrows or drops those that fail. ``report`` (optional) is filled with
    what was done. Samples are at least ``rate_hz`` per second.
    """
    pts = np.atleast_2d(np.asarray(path, dtype=float))
    if pts.ndim != 2 or len(pts) == 0 or not np.all(np.isfinite(pts)):
        raise UserError("time parametrisation: path must be a non-empty (n, dof) array of finite radians")
    if not rate_hz > 0:
        raise UserError(f"time parametrisation: rate_hz must be > 0 (got {rate_hz})")
    if not max_deviation >= 0:
        raise UserError(f"time parametrisation: max_deviation must be >= 0 radians (got {max_deviation})")
    if path_speed is not None and not path_speed > 0:
        raise UserError(f"time parametrisation: path_speed must be > 0 rad/s (got {path_speed})")
    dof = pts.shape[1]
    vel, acc = joint_limits(v_max, dof, "v_max"), joint_limits(a_max, dof, "a_max")
    report = report if report is not None else BlendReport()
    # Repeated waypoints carry no motion; keep the first of each run (their stops move to it).
    keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-12])
    new_index = np.cumsum(keep) - 1
    q = pts[keep]
    stop = np.zeros(len(q), dtype=bool)
    stop[[0, -1]] = True
    for i in stops:
        if not 0 <= int(i) < len(pts):
            raise UserError(f"time parametrisation: stop {i} is not a waypoint index (0..{len(pts) - 1})")
        stop[new_index[int(i)]] = True
    dev = np.full(len(q), float(max_deviation))
    if len(q) >= 3:
        d = np.diff(q, axis=0)
        u = d / np.linalg.norm(d, axis=1)[:, None]
        turn = np.arccos(np.clip(np.einsum("ij,ij->i", u[:-1], u[1:]), -1.0, 1.0))
        stop[1:-1] |= (turn > _MAX_TURN) | ((turn >= MIN_TURN) & (max_deviation <= 0.0))
    dev[stop] = 0.0
    if is_valid is not None and len(q) >= 3:
        for _ in range(3):  # full, half, quarter deviation; then no blend
            bad = [
                i for i, qs in BlendedPath(q, dev).arc_samples(check_step) if not np.all(np.asarray(is_valid(qs), bool))
            ]
            if not bad:
                break
            for i in bad:
                if dev[i] > 0.3 * max_deviation:
                    dev[i] *= 0.5
                    report.narrowed += 1
                else:
                    dev[i], stop[i] = 0.0, True
                    report.unblended += 1
        else:
            for i, qs in BlendedPath(q, dev).arc_samples(check_step):
                if not np.all(np.asarray(is_valid(qs), bool)):
                    dev[i], stop[i] = 0.0, True
                    report.unblended += 1
    cuts = np.flatnonzero(stop)
    report.stops += len(cuts) - 2 if len(q) > 1 else 0
    if len(q) == 1:
        single = time_parametrize(q, vel, acc, rate_hz=rate_hz)
        return TimedPath(
            single.times, single.positions, single.velocities, single.accelerations, np.zeros(len(pts), dtype=int)
        )
    parts = [
        _time_piece(q[a : b + 1], dev[a : b + 1], vel, acc, path_speed, rate_hz, report)
        for a, b in itertools.pairwise(cuts)
    ]
    timed = _concat(parts)
    # waypoint_index for the caller's waypoints (repeats share their first copy's sample)
    timed.waypoint_index = timed.waypoint_index[new_index]
    return timed
