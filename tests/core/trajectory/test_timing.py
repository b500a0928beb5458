from __future__ import annotations

import numpy as np
import pytest

from asmteach.core.errors import UserError
from asmteach.core.models import Trajectory
from asmteach.core.trajectory.timing import segment_profile, time_parametrize, to_trajectory

V = np.array([1.0, 0.5, 2.0])
A = np.array([2.0, 1.0, 4.0])
PATH = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, -0.2], [1.0, 0.5, -0.2], [1.02, 0.49, -0.2], [-0.5, 1.5, 1.0]])


def test_limits_respected_by_samples_and_finite_differences() -> None:
    timed = time_parametrize(PATH, V, A, rate_hz=100.0)
    assert np.all(np.abs(timed.velocities) <= V + 1e-9)
    assert np.all(np.abs(timed.accelerations) <= A + 1e-9)
    dt = np.diff(timed.times)
    assert dt.max() <= 0.01 + 1e-12 and dt.min() >= 0.0
    moving = dt > 0
    fd_v = np.diff(timed.positions, axis=0)[moving] / dt[moving, None]
    # A chord's slope is the mean velocity over the interval, never above the limit.
    assert np.all(np.abs(fd_v) <= V + 1e-9)
    # Second differences inside segments average the acceleration over two intervals.
    t, q = timed.times, timed.positions
    for k in range(1, len(t) - 1):
        if t[k] - t[k - 1] > 0 and t[k + 1] - t[k] > 0:
            v1 = (q[k] - q[k - 1]) / (t[k] - t[k - 1])
            v2 = (q[k + 1] - q[k]) / (t[k + 1] - t[k])
            assert np.all(np.abs(v2 - v1) / (0.5 * (t[k + 1] - t[k - 1])) <= A + 1e-6)


def test_passes_through_waypoints_at_rest() -> None:
    timed = time_parametrize(PATH, V, A)
    assert len(timed.waypoint_index) == len(PATH)
    assert np.allclose(timed.positions[timed.waypoint_index], PATH, atol=1e-12)
    assert np.allclose(timed.velocities[timed.waypoint_index], 0.0)
    assert np.all(np.diff(timed.waypoint_index) >= 0)


def test_positions_stay_on_straight_segments() -> None:
    timed = time_parametrize(PATH[:2], V, A)
    # Every sample is start + s * delta for one s in [0, 1], so all joints are synchronised.
    delta = PATH[1] - PATH[0]
    s = timed.positions @ delta / (delta @ delta)
    assert np.allclose(timed.positions, PATH[0] + s[:, None] * delta, atol=1e-12)
    assert np.all(np.diff(s) >= -1e-12) and np.isclose(s[0], 0.0) and np.isclose(s[-1], 1.0)


def test_segment_profile_analytic_durations() -> None:
    # Long move: trapezoid, 1 rad at 1 rad/s and 2 rad/s^2 -> 0.5 s ramp, 0.5 s cruise, 0.5 s ramp.
    assert segment_profile(np.array([1.0]), np.array([1.0]), np.array([2.0]))[0] == pytest.approx(1.5)
    # Short move: triangle, 0.1 rad at 2 rad/s^2 -> 2 * sqrt(0.05).
    assert segment_profile(np.array([0.1]), np.array([1.0]), np.array([2.0]))[0] == pytest.approx(2 * np.sqrt(0.05))
    # The slowest joint sets the time: joint 1 needs 2 rad at 0.5 rad/s.
    duration = segment_profile(np.array([0.1, 2.0]), np.array([1.0, 0.5]), np.array([10.0, 10.0]))[0]
    assert duration == pytest.approx(2.0 / 0.5 + 0.5 / 10.0)


def test_trajectory_model_and_bad_input() -> None:
    timed = time_parametrize(PATH, 1.0, 2.0)
    traj = to_trajectory(timed, "left", ["j0", "j1", "j2"])
    assert isinstance(traj, Trajectory)
    back = Trajectory.model_validate_json(traj.model_dump_json())
    assert np.allclose(back.positions, timed.positions)
    with pytest.raises(UserError, match="v_max"):
        time_parametrize(PATH, [1.0, 0.0, 1.0], 2.0)
    with pytest.raises(UserError, match="a_max"):
        time_parametrize(PATH, 1.0, [1.0, 1.0])
    single = time_parametrize(PATH[:1], 1.0, 1.0)
    assert single.duration == 0.0 and len(single.times) == 1
