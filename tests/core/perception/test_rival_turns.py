"""Turns of a pose that one depth view may not tell from it: about the rivals' screw axis, about the part's axes,
and the near twins that keep the part's outside."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from asmteach.core import geometry
from asmteach.core.interfaces import PartModel
from asmteach.core.perception.rival_turns import axis_turns, near_twins, screw_turns
from asmteach.core.pose_error import pose_error


def test_turns_about_the_rivals_screw_axis_pass_through_both() -> None:
    T_a = geometry.from_rotation(np.eye(3), [0.4, 0.1, 0.02])
    R = geometry.from_rotvec([0.0, 0.0, np.radians(40.0)])[:3, :3]
    p = np.array([0.45, -0.05, 0.0])  # a vertical axis beside the part
    T_b = geometry.from_rotation(R, p - R @ p) @ T_a
    turns = screw_turns(T_a, T_b, 10.0)
    assert len(turns) == 35
    assert pose_error(turns[3], T_b).within(0.01, 0.01)  # the 40 deg turn lands on T_b


def test_axis_turns_keep_the_centre_of_mass(d_peg_part: PartModel, d_peg_poses) -> None:
    T = d_peg_poses[0]
    com = np.asarray(d_peg_part.mesh.center_mass)
    turns = axis_turns(d_peg_part.mesh, T, 30.0)
    assert len(turns) == 3 * 11
    for Tt in turns:
        assert np.allclose(geometry.transform_points(Tt, com[None]), geometry.transform_points(T, com[None]))


def test_near_twins_are_the_turns_that_keep_the_outside(holed_block) -> None:
    turns = near_twins(holed_block, 10.0, 1.5)
    angles = np.degrees(np.linalg.norm(Rotation.from_matrix(turns[:, :3, :3]).as_rotvec(), axis=1))
    assert len(turns) == 3 and np.allclose(angles, 180.0, atol=1.0)  # a box: half turns about its three axes
    assert len(near_twins(holed_block, 10.0, 0.0)) == 0
