"""The parallel-jaw hand as boxes, and its collision and distance against named meshes."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from asmteach.core.geometry import from_rotation
from asmteach.core.hand_geometry import MeshCollider, hand_boxes, hand_mesh, pad_grid
from asmteach.core.models import HandSpec

HAND = HandSpec(
    name="test_2f",
    max_width=0.085,
    finger_size=[0.010, 0.020, 0.045],
    pad_size=(0.020, 0.030),
    palm_center=[0.0, 0.0, -0.050],
    palm_size=[0.040, 0.100, 0.040],
)


def test_fingers_hang_from_the_palm_with_inner_faces_at_half_the_width() -> None:
    palm, f0, f1 = hand_boxes(HAND, 0.04)
    assert palm.name == "palm" and np.allclose(palm.center, [0.0, 0.0, -0.05])
    for box, sign in ((f0, -1.0), (f1, 1.0)):
        inner = box.center[1] - sign * 0.5 * box.size[1]
        assert inner == pytest.approx(sign * 0.02)
        assert box.center[2] - 0.5 * box.size[2] == pytest.approx(-0.03)  # the palm's front face
    swept = hand_boxes(HAND, 0.04, sweep=0.02)
    assert swept[1].size[2] == pytest.approx(0.065) and swept[1].center[2] == pytest.approx(f0.center[2] - 0.01)


def test_hand_mesh_spans_the_boxes_and_pad_grid_covers_the_pad() -> None:
    mesh = hand_mesh(HAND, 0.04, from_rotation(np.eye(3), [0.0, 0.0, 1.0]))
    assert np.allclose(mesh.bounds, [[-0.02, -0.05, 0.93], [0.02, 0.05, 1.015]])
    grid = pad_grid(HAND, 3, 2, inset=0.001)
    assert grid.shape == (6, 2) and np.allclose(grid.min(axis=0), [-0.009, -0.014])


def test_collider_names_the_pair_and_measures_distance() -> None:
    cube = trimesh.creation.box(extents=[0.02, 0.02, 0.02])
    collider = MeshCollider({"cube": (cube, np.eye(4)), "table": (cube, from_rotation(np.eye(3), [0.0, 0.0, -1.0]))})
    boxes = hand_boxes(HAND, 0.04)
    assert collider.first_contact(boxes, np.eye(4)) is None  # the open jaw straddles the cube
    assert collider.first_contact(hand_boxes(HAND, 0.01), np.eye(4))[1] == "cube"
    assert collider.collides(boxes, from_rotation(np.eye(3), [0.0, 0.0, 0.04]))  # palm on the cube
    ball = trimesh.creation.icosphere(radius=0.01)
    d = collider.distance(ball, from_rotation(np.eye(3), [0.05, 0.0, 0.0]), skip=("table",))
    assert d == pytest.approx(0.03, abs=1e-3)
    assert collider.distance(ball, np.eye(4), skip=("cube", "table")) == np.inf
