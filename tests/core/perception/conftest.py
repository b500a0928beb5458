"""Meshes the perception tests share, made in code."""

from __future__ import annotations

import pytest
import trimesh


@pytest.fixture(scope="session")
def holed_block() -> trimesh.Trimesh:
    """A 60 x 36 x 40 mm block with a blind hole (6 mm radius, 15 mm deep) 12 mm off centre in its bottom face:
    turned 180 deg about its normal it has the same outside, the hole moved."""
    block = trimesh.creation.box(extents=[0.06, 0.036, 0.04])
    hole = trimesh.creation.cylinder(radius=0.006, height=0.03)
    hole.apply_translation([0.012, 0.0, -0.02])
    return block.difference(hole)
