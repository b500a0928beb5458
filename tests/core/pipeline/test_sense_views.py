"""The detect stage's look: every depth camera of the world, each with its own stacked frames and centre."""

from __future__ import annotations

import numpy as np

from asmteach.core.pipeline.detect import sense, sense_views


class _TwoCameras:
    """A world with two depth cameras: camera ``v``'s ``k``-th frame is all ``10 v + k``, its centre ``(v, 0, 1)``."""

    def __init__(self) -> None:
        self.calls = [0, 0]

    def depth_views(self) -> int:
        return 2

    def sense_depth(self, view: int = 0) -> tuple[np.ndarray, np.ndarray]:
        self.calls[view] += 1
        value = 10.0 * view + self.calls[view]
        return np.full((4, 4), value), np.full((5, 3), value)

    def camera_pose(self, view: int = 0) -> np.ndarray:
        T = np.eye(4)
        T[:3, 3] = [view, 0.0, 1.0]
        return T


def test_every_camera_gives_its_own_view() -> None:
    world = _TwoCameras()
    depth, views = sense_views(world, frames=3)  # type: ignore[arg-type]
    assert world.calls == [3, 3] and len(views) == 2
    assert sorted(set(views[0].cloud[:, 0])) == [1.0, 2.0, 3.0]
    assert sorted(set(views[1].cloud[:, 0])) == [11.0, 12.0, 13.0]
    assert np.allclose(views[0].viewpoint, [0.0, 0.0, 1.0]) and np.allclose(views[1].viewpoint, [1.0, 0.0, 1.0])
    assert np.all(depth == 1.0)  # the first camera's first frame


def test_sense_is_the_first_camera_alone() -> None:
    world = _TwoCameras()
    depth, cloud, eye = sense(world, 2)  # type: ignore[arg-type]
    assert world.calls == [2, 0] and cloud.shape == (10, 3)
    assert np.allclose(eye, [0.0, 0.0, 1.0]) and np.all(depth == 1.0)


def test_a_world_that_does_not_know_its_camera_gives_no_centre() -> None:
    class Blind(_TwoCameras):
        def camera_pose(self, view: int = 0) -> np.ndarray:
            raise NotImplementedError

    _, views = sense_views(Blind(), frames=1)  # type: ignore[arg-type]
    assert [v.viewpoint for v in views] == [None, None]
