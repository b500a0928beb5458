"""Insertion load on a part at rest: a block pushed sideways slides, pushed down it stays; a tall one tips."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from asmteach.core.interfaces import PartModel
from asmteach.core.models import PartSpec
from asmteach.core.rests.insertion_load import (
    GRAVITY,
    TABLE_FRICTION,
    insertion_stability,
    seat_friction_n,
    support_polygon,
)


def _block(size: tuple[float, float, float], mass: float) -> PartModel:
    """A box with its frame at the centre of its bottom face (so it stands on the table at the identity)."""
    mesh = trimesh.creation.box(extents=size)
    mesh.apply_translation([0.0, 0.0, 0.5 * size[2]])
    com = np.array([0.0, 0.0, 0.5 * size[2]])
    return PartModel(spec=PartSpec(name="block", mesh="block.stl"), mesh=mesh, mass=mass, center_of_mass=com)


def test_support_polygon_is_the_footprint() -> None:
    poly = support_polygon(_block((0.06, 0.04, 0.02), 0.1), np.eye(4))
    assert len(poly) == 4
    assert np.allclose(
        sorted(map(tuple, np.round(poly, 6))), [(-0.03, -0.02), (-0.03, 0.02), (0.03, -0.02), (0.03, 0.02)]
    )


def test_a_light_block_pushed_sideways_slides() -> None:
    block = _block((0.06, 0.04, 0.02), 0.2)  # 1.96 N of weight, 1.57 N of friction
    s = insertion_stability(block, np.eye(4), [-1.0, 0.0, 0.0], 20.0, [0.0, 0.0, 0.01])
    assert s.slides and not s.holds
    assert s.slide_margin_n == pytest.approx(TABLE_FRICTION * 0.2 * GRAVITY - 20.0)
    assert s.resists_n == pytest.approx(TABLE_FRICTION * 0.2 * GRAVITY)
    assert "slides under 20.0 N" in s.summary()


def test_the_same_block_pushed_down_stays() -> None:
    s = insertion_stability(_block((0.06, 0.04, 0.02), 0.2), np.eye(4), [0.0, 0.0, -1.0], 20.0, [0.01, 0.0, 0.02])
    assert s.holds
    assert s.slide_margin_n == pytest.approx(TABLE_FRICTION * (0.2 * GRAVITY + 20.0))  # the push presses it down
    assert s.tip_margin_nm > 0.0
    assert s.resists_n == float("inf")
    assert s.as_dict()["resists_n"] is None


def test_a_heavy_block_resists_a_small_sideways_push() -> None:
    s = insertion_stability(_block((0.06, 0.04, 0.02), 5.0), np.eye(4), [0.0, 1.0, 0.0], 20.0, [0.0, 0.0, 0.01])
    assert s.holds


def test_a_tall_narrow_block_tips_before_it_slides() -> None:
    # 1 cm wide, 10 cm tall, pushed at its top along +x: weight moment m g 0.005 vs push f 0.1; friction mu m g
    block = _block((0.01, 0.01, 0.1), 1.0)
    s = insertion_stability(block, np.eye(4), [1.0, 0.0, 0.0], 2.0, [0.0, 0.0, 0.1])
    assert s.tips and not s.slides
    assert s.resists_n == pytest.approx(GRAVITY * 0.005 / 0.1)
    pushed_low = insertion_stability(block, np.eye(4), [1.0, 0.0, 0.0], 0.4, [0.0, 0.0, 0.001])
    assert pushed_low.holds


def test_seat_friction_is_b_weight_times_friction() -> None:
    assert seat_friction_n(0.05, 1.0) == pytest.approx(0.05 * GRAVITY)


def test_the_verdict_is_plain_json() -> None:
    s = insertion_stability(_block((0.06, 0.04, 0.02), 0.2), np.eye(4), [-1.0, 0.0, 0.0], 20.0, [0.0, 0.0, 0.01])
    assert json.loads(json.dumps(s.as_dict()))["slides"] is True  # numpy scalars would not serialise
