"""Time parametrisation of a joint path under per-joint velocity and acceleration limits.

Each straight segment between waypoints is executed rest-to-rest with one
trapezoidal velocity profile ``s(t)`` (``s`` from 0 to 1) shared by all joints,
``q(t) = q_i + s(t) (q_{i+1} - q_i)``: the joints start and stop together and
the robot stays exactly on the straight joint-space segment the planner checked
for collisions. The profile's peak rate and acceleration are the largest that
keep every joint within its limits: ``s_dot <= min_j v_j / |dq_j|``,
``s_ddot <= min_j a_j / |dq_j|``; a segment too short to reach the peak rate
gets a triangular profile. This is time-optimal for each segment under the
rest-to-rest, straight-line constraint (not across waypoints; simplified paths
have few of them). Samples are evenly spaced within each segment at no less
than ``rate_hz`` and always include every waypoint at its arrival time.

This is the old timing: a straight TCP line (a waypoint every few millimetres)
stops at every waypoint. Plans are now timed by default with
:mod:`.blended` (toppra through all waypoints, corner blends); this one stays
as ``to_plan(timing="trapezoid")``, the reference of ``benchmarks/cycle_time.py``
and the fall-back where toppra fails or gains nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from asmteach.core.errors import UserError
from asmteach.core.models import Trajectory

__all__ = ["TimedPath", "joint_limits", "segment_profile", "time_parametrize", "to_trajectory"]


@dataclass
class TimedPath:
    """A sampled, time-parametrised joint path.

    ``times`` ``(m,)`` seconds from 0; ``positions``, ``velocities``,
    ``accelerations`` ``(m, dof)`` in rad, rad/s, rad/s^2 (analytic values of
    the profile; at a waypoint the velocity is 0 and the acceleration is that
    of the segment starting there). ``waypoint_index[i]`` is the sample index
    of waypoint ``i``.
    """

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    waypoint_index: np.ndarray

    @property
    def duration(self) -> float:
        """Total time, seconds."""
        return float(self.times[-1])


def segment_profile(delta: np.ndarray, v_max: np.ndarray, a_max: np.ndarray) -> tuple[float, float, float]:
    """Rest-to-rest trapezoid for one segment: ``(duration s, peak s_dot 1/s, s_ddot 1/s^2)``.

    ``delta`` ``(dof,)`` is the joint displacement (rad); limits are per joint.
    A zero segment takes zero time.
    """
    moving = np.abs(delta) > 1e-12
    if not moving.any():
        return 0.0, 0.0, 0.0
    sd = float(np.min(v_max[moving] / np.abs(delta[moving])))
    sdd = float(np.min(a_max[moving] / np.abs(delta[moving])))
    if sd * sd / sdd >= 1.0:
        # Triangular: accelerate over half the segment, then brake.
        t_acc = np.sqrt(1.0 / sdd)
        return 2.0 * t_acc, sdd * t_acc, sdd
    t_acc = sd / sdd
    cruise = (1.0 - sd * t_acc) / sd
    return 2.0 * t_acc + cruise, sd, sdd


def _profile_at(t: np.ndarray, duration: float, sd: float, sdd: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``s, s_dot, s_ddot`` of a trapezoid (peak ``sd``, acceleration ``sdd``) at times ``t`` in ``[0, duration]``."""
    t_acc = sd / sdd
    s = np.empty_like(t)
    v = np.empty_like(t)
    a = np.empty_like(t)
    acc = t < t_acc
    dec = t > duration - t_acc
    cru = ~(acc | dec)
    s[acc], v[acc], a[acc] = 0.5 * sdd * t[acc] ** 2, sdd * t[acc], sdd
    s[cru], v[cru], a[cru] = 0.5 * sdd * t_acc**2 + sd * (t[cru] - t_acc), sd, 0.0
    r = duration - t[dec]
    s[dec], v[dec], a[dec] = 1.0 - 0.5 * sdd * r**2, sdd * r, -sdd
    return np.clip(s, 0.0, 1.0), v, a


def joint_limits(value: float | np.ndarray, dof: int, name: str) -> np.ndarray:
    """``value`` (one number or one per joint) as ``(dof,)`` positive finite limits; :class:`UserError` otherwise."""
    arr = np.asarray(value, dtype=float)
    arr = np.full(dof, float(arr)) if arr.ndim == 0 else arr.reshape(-1)
    if arr.shape != (dof,) or not np.all(np.isfinite(arr)) or not np.all(arr > 0):
        raise UserError(f"time parametrisation: {name} must be {dof} finite values > 0 (got {np.asarray(value)!r})")
    return arr


def time_parametrize(
    path: np.ndarray,
    v_max: float | np.ndarray,
    a_max: float | np.ndarray,
    *,
    rate_hz: float = 100.0,
) -> TimedPath:
    """Time-parametrise ``path`` ``(n, dof)`` (radians) under ``v_max`` (rad/s) and ``a_max`` (rad/s^2).

    Limits are scalars or ``(dof,)`` per joint. Returns samples at least every
    ``1 / rate_hz`` seconds, passing through every waypoint.
    """
    pts = np.atleast_2d(np.asarray(path, dtype=float))
    if pts.ndim != 2 or len(pts) == 0 or not np.all(np.isfinite(pts)):
        raise UserError("time parametrisation: path must be a non-empty (n, dof) array of finite radians")
    if not rate_hz > 0:
        raise UserError(f"time parametrisation: rate_hz must be > 0 (got {rate_hz})")
    dof = pts.shape[1]
    vel = joint_limits(v_max, dof, "v_max")
    acc = joint_limits(a_max, dof, "a_max")
    times = [np.zeros(1)]
    pos = [pts[:1]]
    vels = [np.zeros((1, dof))]
    accs = [np.zeros((1, dof))]
    index = [0]
    t0 = 0.0
    count = 1
    for i in range(len(pts) - 1):
        delta = pts[i + 1] - pts[i]
        duration, sd, sdd = segment_profile(delta, vel, acc)
        if duration == 0.0:
            index.append(count - 1)  # a repeated waypoint shares the previous sample
            continue
        n = max(1, int(np.ceil(duration * rate_hz - 1e-9)))
        t = np.linspace(0.0, duration, n + 1)
        s, v, a = _profile_at(t, duration, sd, sdd)
        # The sample at t = 0 is the previous waypoint; give it this segment's starting acceleration.
        accs[-1][-1] = a[0] * delta
        times.append(t0 + t[1:])
        pos.append(pts[i] + s[1:, None] * delta)
        pos[-1][-1] = pts[i + 1]  # exact waypoint, no rounding drift
        vels.append(v[1:, None] * delta)
        vels[-1][-1] = 0.0
        accs.append(a[1:, None] * delta)
        accs[-1][-1] = 0.0
        t0 += duration
        count += n
        index.append(count - 1)
    return TimedPath(
        times=np.concatenate(times),
        positions=np.vstack(pos),
        velocities=np.vstack(vels),
        accelerations=np.vstack(accs),
        waypoint_index=np.array(index, dtype=int),
    )


def to_trajectory(timed: TimedPath, arm: str, joint_names: list[str]) -> Trajectory:
    """The :class:`~asmteach.core.models.Trajectory` of ``arm`` for a :class:`TimedPath`."""
    return Trajectory(arm=arm, joint_names=list(joint_names), times=timed.times.tolist(), positions=timed.positions)
