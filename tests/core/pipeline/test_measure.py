"""The assembly error of the measure stage: a turn about B's axis of revolution is no error."""

from __future__ import annotations

import numpy as np
import trimesh

from asmteach.core import geometry
from asmteach.core.interfaces import PartModel
from asmteach.core.models import PartSpec
from asmteach.core.pipeline.measure import assembly_error, revolution_axis
from asmteach.core.pose_error import pose_error
from asmteach.core.symmetry import part_symmetries


def _part(mesh: trimesh.Trimesh, name: str) -> PartModel:
    return PartModel(
        spec=PartSpec(name=name, mesh=f"{name}.stl"), mesh=mesh, mass=0.05, center_of_mass=mesh.center_mass
    )


def _peg() -> PartModel:
    """A round peg 16 mm across, 40 mm long, its axis along z, the part frame at its bottom face."""
    mesh = trimesh.creation.cylinder(radius=0.008, height=0.04, sections=64)
    mesh.apply_translation([0.0, 0.0, 0.02])
    return _part(mesh, "peg")


def test_a_round_peg_has_an_axis_of_revolution_and_a_square_one_has_none() -> None:
    axis = revolution_axis(_peg())
    assert axis is not None
    assert abs(abs(axis[2]) - 1.0) < 1e-6
    square = trimesh.creation.box((0.016, 0.016, 0.04))
    assert revolution_axis(_part(square, "square_peg")) is None


def test_a_turn_about_the_pegs_axis_is_left_out_and_its_tilt_is_not() -> None:
    peg = _peg()
    com = np.asarray(peg.center_of_mass)
    sym = part_symmetries(peg.mesh, com)
    axis = revolution_axis(peg)
    T_ref = geometry.from_rpy(0.0, 0.0, 0.0, (0.01, 0.0, 0.02))
    # turned 4.7 deg about its own axis (between two of the group's 10 deg samples), tilted 0.6 deg about x
    turn = geometry.from_rotation(
        geometry.rot_z(np.radians(4.7))[:3, :3], com - geometry.rot_z(np.radians(4.7))[:3, :3] @ com
    )
    tilt = geometry.from_rpy(np.radians(0.6), 0.0, 0.0)
    T = T_ref @ turn @ tilt
    old = pose_error(T, T_ref, (), sym)
    new = assembly_error(T, T_ref, (), sym, axis, com)
    assert old.angle_deg > 4.0  # the group's nearest sample is 4.7 deg away
    assert abs(new.angle_deg - 0.6) < 0.05
    # a part with no axis of revolution is measured as before
    plain = assembly_error(T, T_ref, (), sym, None, com)
    assert plain.angle_deg == old.angle_deg
