"""The one pose-error vocabulary: plain and symmetry-aware errors against known values."""

from __future__ import annotations

import numpy as np
import pytest

from asmteach.core import geometry
from asmteach.core.pose_error import nearest_symmetric, pose_error


def test_plain_error_has_known_values() -> None:
    ref = geometry.from_rpy(0.1, -0.2, 0.3, (0.1, 0.2, 0.3))
    est = geometry.from_rotation(
        geometry.rot_z(np.radians(2.0))[:3, :3] @ ref[:3, :3], ref[:3, 3] + (0.003, -0.004, 0.0)
    )
    err = pose_error(est, ref)
    assert err.position_mm == pytest.approx(5.0)
    assert err.angle_deg == pytest.approx(2.0)
    assert err.dxyz_mm == pytest.approx((3.0, -4.0, 0.0))
    assert err.drpy_deg == pytest.approx((0.0, 0.0, 2.0), abs=1e-9)
    assert err.as_dict()["position_mm"] == pytest.approx(5.0)
    assert err.within(5.01, 2.01) and not err.within(4.9, 2.01)


def test_tiny_angles_stay_precise() -> None:
    ref = np.eye(4)
    est = geometry.from_rpy(1e-7, 0.0, 0.0)
    assert pose_error(est, ref).angle_deg == pytest.approx(np.degrees(1e-7), rel=1e-6)


def test_a_symmetry_of_the_part_is_the_same_answer() -> None:
    half_turn = geometry.from_rpy(0.0, 0.0, np.pi)  # a box about its z axis through the origin
    ref = geometry.from_rpy(0.0, 0.0, 0.4, (0.2, 0.0, 0.05))
    seen = ref @ half_turn @ geometry.from_rpy(0.0, 0.0, np.radians(0.5))
    assert pose_error(seen, ref).angle_deg == pytest.approx(179.5)
    assert pose_error(seen, ref, right=[np.eye(4), half_turn]).angle_deg == pytest.approx(0.5)
    near = nearest_symmetric(seen, ref, [np.eye(4), half_turn])
    assert pose_error(near, ref).angle_deg == pytest.approx(0.5)


def test_left_symmetries_act_in_the_reference_frame() -> None:
    # T_A_B of a pin in a symmetric block: A turned by its own symmetry is the same assembly.
    sym_a = geometry.from_rpy(0.0, 0.0, np.pi / 2)
    T_A_B = geometry.from_rpy(0.0, 0.0, 0.0, (0.01, 0.0, 0.02))
    seen = geometry.invert(sym_a) @ T_A_B
    assert pose_error(seen, T_A_B).position_mm > 5.0
    assert pose_error(seen, T_A_B, left=[np.eye(4), sym_a]).position_mm == pytest.approx(0.0, abs=1e-9)


def test_the_nearest_equivalent_weighs_millimetres_and_degrees_together() -> None:
    # One equivalent is 3 mm off and aligned, the other in place but 10 deg off: 3 < 10 wins.
    shifted = geometry.from_rotation(np.eye(3), (0.003, 0.0, 0.0))
    turned = geometry.from_rpy(0.0, 0.0, np.radians(10.0))
    err = pose_error(np.eye(4), np.eye(4), right=[geometry.invert(shifted), geometry.invert(turned)])
    assert err.position_mm == pytest.approx(3.0) and err.angle_deg == pytest.approx(0.0, abs=1e-6)
