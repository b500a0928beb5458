"""The blended, time-optimal timing (toppra) against the rest-to-rest trapezoid."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from asmteach.core.errors import UserError
from asmteach.core.trajectory.blended import BlendReport, time_optimal
from asmteach.core.trajectory.blended_path import BlendedPath
from asmteach.core.trajectory.timing import time_parametrize

V = np.array([1.0, 0.5, 2.0])  # rad/s
A = np.array([2.0, 1.0, 4.0])  # rad/s^2
PATH = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, -0.2], [1.0, 0.5, -0.2], [1.02, 0.49, -0.2], [-0.5, 1.5, 1.0]])


def _arc(n: int = 25) -> np.ndarray:
    """A dense curved path, like the joint path of a straight TCP line (small turn at every waypoint)."""
    s = np.linspace(0.0, 1.0, n)
    return np.stack([np.sin(s), 0.5 * np.cos(s), s**2], axis=1)


def _distance_to_polyline(q: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Euclidean distance (rad) of each of ``q`` to the nearest point of the polyline ``pts``."""
    best = np.full(len(q), np.inf)
    for a, b in itertools.pairwise(pts):
        d = b - a
        if d @ d == 0:
            continue
        t = np.clip((q - a) @ d / (d @ d), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(q - (a + t[:, None] * d), axis=1))
    return best


@pytest.mark.parametrize("path", [PATH, _arc()], ids=["corners", "dense"])
def test_limits_respected_at_every_sample_and_between(path: np.ndarray) -> None:
    timed = time_optimal(path, V, A, rate_hz=100.0)
    assert np.all(np.abs(timed.velocities) <= V * (1 + 1e-6))
    assert np.all(np.abs(timed.accelerations) <= A * (1 + 1e-6))
    dt = np.diff(timed.times)
    assert dt.min() > 0 and dt.max() <= 0.01 + 1e-9
    # chord slopes (what the robot's linear interpolation between samples commands) stay within the limits
    chord = np.diff(timed.positions, axis=0) / dt[:, None]
    assert np.all(np.abs(chord) <= V * (1 + 1e-6))
    # second differences average the acceleration over two intervals
    v1, v2 = chord[:-1], chord[1:]
    second = (v2 - v1) / (0.5 * (dt[1:] + dt[:-1]))[:, None]
    assert np.all(np.abs(second) <= A * (1 + 1e-6))


def test_ends_at_rest_on_the_first_and_last_waypoints_and_passes_the_others_within_the_deviation() -> None:
    for dev in (0.005, 0.05):
        timed = time_optimal(PATH, V, A, max_deviation=dev)
        np.testing.assert_allclose(timed.positions[0], PATH[0], atol=1e-12)
        np.testing.assert_allclose(timed.positions[-1], PATH[-1], atol=1e-12)
        assert np.allclose(timed.velocities[[0, -1]], 0.0)
        assert len(timed.waypoint_index) == len(PATH)
        assert np.all(np.diff(timed.waypoint_index) >= 0)
        # every waypoint is passed within the deviation (plus the sampling's 10 ms of motion)
        for w in PATH:
            assert np.min(np.linalg.norm(timed.positions - w, axis=1)) <= dev + 0.01 * np.linalg.norm(V)
        # and the whole path stays within the deviation of the checked polyline
        assert _distance_to_polyline(timed.positions, PATH).max() <= dev + 1e-9


def test_blends_keep_moving_and_stops_are_kept_where_asked() -> None:
    path = _arc()
    report = BlendReport()
    timed = time_optimal(path, V, A, report=report)
    inner = timed.waypoint_index[1:-1]
    assert report.blended == len(path) - 2 and report.stops == 0
    assert np.all(np.linalg.norm(timed.velocities[inner], axis=1) > 0.05)  # no stop at any waypoint
    report = BlendReport()
    timed = time_optimal(path, V, A, stops=[12], report=report)
    k = timed.waypoint_index[12]
    np.testing.assert_allclose(timed.positions[k], path[12], atol=1e-12)
    assert np.allclose(timed.velocities[k], 0.0)
    assert report.stops == 1


def test_shorter_than_the_trapezoid_on_a_multi_waypoint_path() -> None:
    for path in (PATH, _arc()):
        old = time_parametrize(path, V, A).duration
        new = time_optimal(path, V, A).duration
        assert new <= old  # never slower: where toppra gains nothing the trapezoid is kept
    # the dense path: the trapezoid stops 23 times, the blended path never
    assert time_optimal(_arc(), V, A).duration < 0.5 * time_parametrize(_arc(), V, A).duration


def test_a_straight_two_point_move_matches_the_trapezoid() -> None:
    path = PATH[:2]
    old = time_parametrize(path, V, A).duration
    report = BlendReport()
    new = time_optimal(path, V, A, report=report).duration
    assert new == pytest.approx(old, rel=1e-9)  # toppra is no faster on one straight move: the trapezoid is kept
    assert report.trapezoid_pieces == 1


def test_path_speed_caps_the_joint_space_speed() -> None:
    timed = time_optimal(_arc(), V, A, path_speed=0.1)
    assert np.linalg.norm(timed.velocities, axis=1).max() <= 0.1 * (1 + 1e-6)
    length = np.sum(np.linalg.norm(np.diff(_arc(), axis=0), axis=1))
    assert timed.duration >= length / 0.1


def test_collision_recheck_narrows_a_blend_that_cuts_into_an_obstacle() -> None:
    """An obstacle inside the corner, clear of both segments: the full blend cuts it, a narrower one does not."""
    turn = np.radians(30.0)
    path = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0 + np.cos(turn), np.sin(turn), 0.0]])
    bisector = np.array([-np.sin(0.5 * turn), np.cos(0.5 * turn), 0.0])  # into the corner
    centre, radius = path[1] + 0.04 * bisector, 0.012  # 38 mrad from both segments

    def is_valid(qs: np.ndarray) -> np.ndarray:
        return np.linalg.norm(np.atleast_2d(qs) - centre, axis=1) > radius

    # the straight segments themselves are free (the planner's check, here exact)
    assert _distance_to_polyline(centre[None], path)[0] > 3 * radius
    # unchecked, the 50 mrad blend passes 10 mrad from the centre
    free = time_optimal(path, V, A, max_deviation=0.05)
    assert not is_valid(free.positions).all()
    report = BlendReport()
    timed = time_optimal(path, V, A, max_deviation=0.05, is_valid=is_valid, check_step=0.002, report=report)
    assert is_valid(timed.positions).all()
    assert report.narrowed == 1 and report.unblended == 0 and report.blended == 1
    assert np.linalg.norm(timed.velocities[timed.waypoint_index[1]]) > 0.0  # still no stop at the corner


def test_collision_recheck_falls_back_to_a_stop_when_no_blend_is_free() -> None:
    path = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]])

    def is_valid(qs: np.ndarray) -> np.ndarray:
        # everything off the two segments is "in collision": only the checked polyline is free
        qs = np.atleast_2d(qs)
        return (np.abs(qs[:, 1]) < 1e-12) | (np.abs(qs[:, 0] - 1.0) < 1e-12)

    report = BlendReport()
    timed = time_optimal(path, V, A, is_valid=is_valid, report=report)
    assert report.unblended == 1 and report.stops == 1
    assert is_valid(timed.positions).all()
    assert np.allclose(timed.velocities[timed.waypoint_index[1]], 0.0)
    assert timed.duration == pytest.approx(time_parametrize(path, V, A).duration, rel=0.03)


def test_blended_path_geometry() -> None:
    path = BlendedPath(PATH[[0, 1, 4]], np.array([0.0, 0.01, 0.0]))
    s = np.linspace(*path.path_interval, 20001)
    # unit speed in arc length, tangent continuous, the ends exact
    np.testing.assert_allclose(np.linalg.norm(path(s, 1), axis=1), 1.0, atol=1e-9)
    assert np.max(np.linalg.norm(np.diff(path(s, 1), axis=0), axis=1)) < 0.2
    np.testing.assert_allclose(path(s[[0, -1]]), PATH[[0, 4]], atol=1e-12)
    # finite differences of positions agree with the first derivative
    fd = np.diff(path(s), axis=0) / np.diff(s)[:, None]
    np.testing.assert_allclose(fd, 0.5 * (path(s[:-1], 1) + path(s[1:], 1)), atol=3e-3)


def test_a_straight_waypoint_is_no_corner() -> None:
    # Along this direction the two unit vectors are equal, yet their dot product rounds to just below 1
    # (a "turn" of ~2e-8 rad): the path must stay a straight line, not an arc about a NaN centre.
    d = np.random.default_rng(0).normal(size=(226, 6))[225]
    pts = np.array([np.zeros(6), 0.1 * d, 0.3 * d])
    u = np.diff(pts, axis=0) / np.linalg.norm(np.diff(pts, axis=0), axis=1)[:, None]
    assert np.array_equal(u[0], u[1]) and np.arccos(np.clip(u[0] @ u[1], -1.0, 1.0)) > 1e-9  # the case
    path = BlendedPath(pts, np.array([0.0, 0.005, 0.0]))
    assert path.arcs == []
    s = np.linspace(*path.path_interval, 101)
    assert np.all(np.isfinite(path(s))) and np.allclose(path(s[[0, -1]]), pts[[0, 2]])


def test_deterministic_and_bad_input() -> None:
    a, b = time_optimal(PATH, V, A), time_optimal(PATH, V, A)
    np.testing.assert_array_equal(a.times, b.times)
    np.testing.assert_array_equal(a.positions, b.positions)
    single = time_optimal(PATH[:1], V, A)
    assert single.duration == 0.0
    with pytest.raises(UserError, match="v_max"):
        time_optimal(PATH, [1.0, 0.0, 1.0], A)
    with pytest.raises(UserError, match="max_deviation"):
        time_optimal(PATH, V, A, max_deviation=-1.0)
    with pytest.raises(UserError, match="path_speed"):
        time_optimal(PATH, V, A, path_speed=0.0)
    with pytest.raises(UserError, match="stop 9"):
        time_optimal(PATH, V, A, stops=[9])
