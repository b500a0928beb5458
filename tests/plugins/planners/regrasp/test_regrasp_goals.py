"""Whether B stays in A where it is let go (goals.slides_out), and A's goal placements ranked by it.

Fixtures made in code: a 40 mm cube block A with a 21 mm square through hole along its z, a 20 mm square
slider B (20 mm long, or 40 mm: the hole's full length), and a headed peg (a 30 x 30 x 5 mm head on a
20 mm square shank 30 mm long).
"""

import numpy as np
import pytest

from asmteach.core import geometry
from asmteach.core.models import AssemblyTask, PartSpec, Primitive, SolidSpec
from asmteach.core.parts import build_part
from asmteach.core.rests.placements import compute_placements
from asmteach.plugins.planners.regrasp.goals import (
    a_under_insertion,
    ranked_assembly_goals,
    slides_out,
    snap_to_faces,
)

DOWN = np.array([0.0, 0.0, -1.0])


def _box(size, xyz) -> Primitive:
    return Primitive(shape="box", size=list(size), pose={"xyz": list(xyz)})


@pytest.fixture(scope="module")
def block():
    hole = _box([0.021, 0.021, 0.06], [0, 0, 0.02])
    return build_part(PartSpec(name="block", solid=SolidSpec(add=[_box([0.04] * 3, [0, 0, 0.02])], subtract=[hole])))


def _slider(length: float):
    return build_part(PartSpec(name="slider", solid=SolidSpec(add=[_box([0.02, 0.02, length], [0, 0, length / 2])])))


def _at(z: float) -> np.ndarray:
    return geometry.from_rotation(np.eye(3), [0.0, 0.0, z])


def test_a_slider_in_a_through_hole_stood_on_end_falls_unless_it_reaches_the_table(block) -> None:
    short, full = _slider(0.02), _slider(0.04)
    assert slides_out(block, short, np.eye(4), _at(0.01), DOWN, 0.0)  # 10 mm above the table: it drops
    assert not slides_out(block, full, np.eye(4), _at(0.0), DOWN, 0.0)  # standing on the table
    assert slides_out(block, full, np.eye(4), _at(0.0), DOWN, -0.005)  # the table 5 mm lower: it drops


def test_a_headed_peg_rests_on_its_head_and_a_lying_slot_holds_its_slider(block) -> None:
    head, shank = _box([0.03, 0.03, 0.005], [0, 0, 0.0325]), _box([0.02, 0.02, 0.03], [0, 0, 0.015])
    peg = build_part(PartSpec(name="peg", solid=SolidSpec(add=[head, shank])))
    assert not slides_out(block, peg, np.eye(4), _at(0.01), DOWN, 0.0)  # the head on A's top face
    # A on its side: the hole along world x, the short slider in its middle rests on the hole's wall
    T_a = geometry.from_rpy(0.0, np.pi / 2, 0.0, t=[0.0, 0.0, 0.02])
    T_b = T_a @ _at(0.01)
    assert not slides_out(block, _slider(0.02), T_a, T_b, T_a[:3, :3] @ [0, 0, -1.0], 0.0)


def test_goals_where_b_is_held_come_first(block) -> None:
    """The short slider taught in the middle of the hole: stood on end (insertion straight down) it drops
    out, lying on a side it stays, so a lying placement comes first although its insertion is horizontal."""
    task = AssemblyTask(name="slide", part_a=block.spec, part_b=_slider(0.02).spec, T_A_B=_at(0.01), v_a=[0, 0, -1])
    goals = ranked_assembly_goals(
        block, _slider(0.02), task, compute_placements(block), xy=(0.4, 0.0), yaw=0.0, table_height=0.0, retract=0.05
    )
    held = [g.held for g in goals]
    assert held[0] and not all(held) and held == sorted(held, reverse=True)
    assert abs(goals[0].v_world[2]) < 1e-9
    assert not goals[-1].held and goals[-1].v_world[2] == pytest.approx(-1.0)


def test_a_light_block_slides_under_a_sideways_insertion_not_under_one_from_above(block) -> None:
    """The same goals: lying, B goes in sideways and the guarded insertion's 20 N drags the block (tens of grams)
    across the table; stood on end, B's push presses it onto the table. A lighter push (B's seat friction) the
    lying block resists."""
    slider = _slider(0.02)
    task = AssemblyTask(name="slide", part_a=block.spec, part_b=slider.spec, T_A_B=_at(0.01), v_a=[0, 0, -1])
    goals = ranked_assembly_goals(
        block, slider, task, compute_placements(block), xy=(0.4, 0.0), yaw=0.0, table_height=0.0, retract=0.05
    )
    lying, standing = goals[0].a_load, goals[-1].a_load
    assert lying is not None and standing is not None
    assert lying.force_n == pytest.approx(20.0) and lying.slides
    assert standing.holds and not standing.slides
    assert 0.0 < lying.resists_n < 20.0
    assert a_under_insertion(block, slider, goals[0], force_n=0.5 * lying.resists_n).holds


def test_a_taught_direction_a_degree_off_a_face_normal_is_snapped_to_it(block) -> None:
    """The hole runs along the block's z: a v_a taught 1 deg off it is made exactly -z, one 5 deg off is kept."""
    snap = float(np.radians(2.0))
    one = geometry.from_rpy(np.radians(1.0), 0.0, 0.0)[:3, :3] @ DOWN
    assert snap_to_faces(one, block, snap) == pytest.approx(DOWN)
    five = geometry.from_rpy(np.radians(5.0), 0.0, 0.0)[:3, :3] @ DOWN
    assert snap_to_faces(five, block, snap) == pytest.approx(five)
    assert snap_to_faces(one, block, 0.0) == pytest.approx(one)  # snapping off
