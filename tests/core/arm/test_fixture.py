"""The jig: when it holds A (auto / always / never against the planner's verdict), and that the simulated jig
keeps a light block put under a sideways push that slides it across the table without one."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from asmteach.core.arm.fixture import clamp_part, jig_decision, jig_key
from asmteach.core.arm.sim import PyBulletWorld
from asmteach.core.interfaces import PartModel
from asmteach.core.models import PartSpec
from asmteach.core.rests.insertion_load import insertion_stability

SLIDES = {"holds": False, "summary": "slides under 20.0 N along (-1.00, +0.00, +0.00)"}
STAYS = {"holds": True, "summary": "stays under 20.0 N along (+0.00, +0.00, -1.00)"}


@pytest.mark.parametrize(
    ("mode", "load", "hold", "says"),
    [
        ("auto", SLIDES, True, "A held by a jig during the insertion: at its goal it slides"),
        ("auto", STAYS, False, ""),
        ("always", STAYS, True, "A held by a jig during the insertion (execution.fixture: always)"),
        ("never", SLIDES, False, "A not held although it may move (execution.fixture: never)"),
        ("auto", None, False, "A not held: the planner did not check"),
    ],
)
def test_jig_decision(mode: str, load: dict | None, hold: bool, says: str) -> None:
    d = jig_decision(mode, "A", load)  # type: ignore[arg-type]
    assert d.hold is hold
    assert d.note.startswith(says) if says else d.note == ""


def _block(size: tuple[float, float, float], mass: float) -> PartModel:
    mesh = trimesh.creation.box(extents=size)
    mesh.apply_translation([0.0, 0.0, 0.5 * size[2]])
    return PartModel(
        spec=PartSpec(name="block", mesh="block.stl"),
        mesh=mesh,
        mass=mass,
        center_of_mass=np.array([0, 0, size[2] / 2]),
    )


def _pushed(tmp_path: Path, clamp: bool) -> float:
    """Metres a 0.2 kg block on the table moves under 20 N along -x for 0.25 s (a T-slider's push)."""
    urdf = tmp_path / "robot.urdf"
    urdf.write_text('<robot name="none"><link name="base"/></robot>')
    world = PyBulletWorld(urdf, np.eye(4))
    try:
        block = _block((0.06, 0.04, 0.02), 0.2)
        T = np.eye(4)
        T[:3, 3] = [0.4, 0.0, 0.0]
        world.reset_world([0.4, 0.0], [0.6, 0.6], 0.0, {"A": (block, T)})
        world.step(60)  # settle on the table
        if clamp:
            assert clamp_part(type("Robot", (), {"sim": world})(), "A")
            assert jig_key("A") in world.constraints
        start = world.part_pose("A")[:3, 3].copy()
        body, _ = world.parts["A"]
        for _ in range(60):
            pos, _ = world.p.getBasePositionAndOrientation(body)
            world.p.applyExternalForce(body, -1, [-20.0, 0.0, 0.0], pos, world.p.WORLD_FRAME)
            world.step(1)
        return float(np.linalg.norm(world.part_pose("A")[:3, 3] - start))
    finally:
        world.close()


def test_the_check_and_the_simulation_agree_a_light_block_slides_unless_clamped(tmp_path: Path) -> None:
    verdict = insertion_stability(_block((0.06, 0.04, 0.02), 0.2), np.eye(4), [-1.0, 0.0, 0.0], 20.0, [0, 0, 0.01])
    assert verdict.slides
    assert _pushed(tmp_path, clamp=False) > 0.01  # metres: the push drags it across the table
    assert _pushed(tmp_path, clamp=True) < 0.0005


def test_clamp_needs_a_simulated_world() -> None:
    assert clamp_part(object(), "A") is False
