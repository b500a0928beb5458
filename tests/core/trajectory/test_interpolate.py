from __future__ import annotations

import numpy as np
import pytest

from asmteach.core.trajectory.interpolate import densify, densify_tcp, first_invalid


def planar_tcp(q: np.ndarray) -> np.ndarray:
    """TCP of a planar 2-link arm with 0.4 m links, metres."""
    x = 0.4 * np.cos(q[0]) + 0.4 * np.cos(q[0] + q[1])
    y = 0.4 * np.sin(q[0]) + 0.4 * np.sin(q[0] + q[1])
    return np.array([x, y, 0.0])


def test_densify_keeps_waypoints_and_bounds_step() -> None:
    path = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [1.0, 1.0], [0.0, 0.3]])
    dense = densify(path, 0.07)
    steps = np.linalg.norm(np.diff(dense, axis=0), axis=1)
    assert steps.max() <= 0.07 + 1e-12
    for q in path:
        assert np.min(np.linalg.norm(dense - q, axis=1)) < 1e-12
    assert np.allclose(dense[0], path[0]) and np.allclose(dense[-1], path[-1])
    with pytest.raises(ValueError):
        densify(path, 0.0)


def test_densify_tcp_moves_at_most_5mm() -> None:
    path = np.array([[0.0, 0.5], [1.2, -0.4], [0.3, 1.5]])
    dense = densify_tcp(path, planar_tcp, 0.005)
    tcp = np.array([planar_tcp(q) for q in dense])
    assert np.linalg.norm(np.diff(tcp, axis=0), axis=1).max() <= 0.005 + 1e-12
    assert np.allclose(dense[0], path[0]) and np.allclose(dense[-1], path[-1])
    # Samples lie on the joint-space segments, in order: joint 0 is monotonic on the first segment.
    first = dense[: np.flatnonzero(np.all(np.isclose(dense, path[1]), axis=1))[0] + 1]
    assert np.all(np.diff(first[:, 0]) > 0)


def test_first_invalid() -> None:
    path = np.linspace([0.0], [1.0], 11)
    assert first_invalid(path, lambda q: bool(q[0] < 0.55)) == 6
    assert first_invalid(path, lambda q: True) == -1
