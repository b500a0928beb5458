"""NearSymmetry: two poses are the same answer when they put the part's surface in the same place."""

from __future__ import annotations

import numpy as np
import trimesh

from asmteach.core import geometry
from asmteach.core.symmetry.near import NearSymmetry


def _turn(deg: float, axis: tuple[float, float, float] = (0.0, 0.0, 1.0), shift=(0.0, 0.0, 0.0)) -> np.ndarray:
    T = geometry.from_rotvec(np.radians(deg) * np.asarray(axis, float))
    T[:3, 3] += shift
    return T


def test_a_tessellated_cylinder_turned_about_its_axis_is_the_same_answer_a_box_is_not() -> None:
    # 16 segments of a 20 mm radius sag 0.38 mm: every turn about the axis keeps the surface within 0.5 mm,
    # though only the 16 exact turns are symmetries of the mesh
    cyl = NearSymmetry(trimesh.creation.cylinder(radius=0.02, height=0.03, sections=16))
    B = geometry.from_rotation(np.eye(3), (0.45, 0.0, 0.1))
    for deg in (8.0, 11.25, 40.0):
        A = B @ _turn(deg, shift=(0.0008, -0.0005, 0.0003))  # a registration's sub-mm shift on top
        assert cyl.same(A, B), deg
    assert not cyl.same(B @ _turn(8.0, axis=(1.0, 0.0, 0.0)), B)  # tilted off its axis: another pose
    assert not cyl.same(B @ _turn(0.0, shift=(0.0, 0.0, 0.006)), B)  # the same surface 6 mm away: the shift

    box = NearSymmetry(trimesh.creation.box((0.054, 0.040, 0.030)))
    assert box.same(B @ _turn(180.0), B)  # an exact symmetry
    assert not box.same(B @ _turn(8.0), B)  # corners 4 mm off
    assert not box.same(B @ _turn(90.0), B)  # 54 x 40: not square
    assert box.apart(B @ _turn(0.0, shift=(0.002, 0.0, 0.0)), B) < 2.5  # mm, the shift refit measured


def test_a_hex_prism_turned_8_deg_is_not_the_same_answer() -> None:
    hexa = NearSymmetry(trimesh.creation.cylinder(radius=0.009, height=0.04, sections=6))
    assert hexa.gap(_turn(60.0)) < 1e-4
    assert hexa.gap(_turn(8.0)) > hexa.tol
    assert not hexa.same(_turn(8.0), np.eye(4))
