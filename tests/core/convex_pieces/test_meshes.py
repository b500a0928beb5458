"""Convex pieces of parts given as meshes (millimetre STL, as CAD sends them): fidelity, cache, PyBullet insertion.

A peg in a 0.5 mm-clearance hole and a square key in a 0.3 mm-clearance slot,
both written as millimetre STL files and loaded through ``build_part`` (the
mesh route, not the parametric one), must go in to the full depth in PyBullet
when driven down the axis with a modest force; the same peg must not enter a
hole 0.5 mm smaller than itself.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pybullet
import pytest
import trimesh

from asmteach.core.convex_pieces import DecompositionSettings, decompose, fidelity, route
from asmteach.core.models import PartSpec
from asmteach.core.parts import build_part

_FAST = DecompositionSettings(samples=4000)
"""Fewer fidelity samples than the default: the tests check the pieces, the benchmark the figures."""


def _stl_part(tmp_path: Path, name: str, mesh_m: trimesh.Trimesh):
    """Write ``mesh_m`` (metres) as a millimetre STL and load it back as a mesh part."""
    path = tmp_path / f"{name}.stl"
    mm = mesh_m.copy()
    mm.apply_scale(1000.0)
    mm.export(path)
    part = build_part(PartSpec(name=name, mesh=str(path), mesh_units="mm"))
    assert part.spec.solid is None
    return part


def _block_with_pocket(pocket: trimesh.Trimesh, size=(0.04, 0.04, 0.03)) -> trimesh.Trimesh:
    """A block on z = 0 .. size[2] with ``pocket`` cut from its top."""
    block = trimesh.creation.box(extents=size)
    block.apply_translation([0, 0, 0.5 * size[2]])
    return block.difference(pocket, engine="manifold")


def _round_hole_block(radius: float, depth: float = 0.02) -> trimesh.Trimesh:
    cut = trimesh.creation.cylinder(radius=radius, height=depth + 0.01, sections=64)
    cut.apply_translation([0, 0, 0.03 - depth + 0.5 * (depth + 0.01)])
    return _block_with_pocket(cut)


def _square_slot_block(width: float, depth: float = 0.02) -> trimesh.Trimesh:
    cut = trimesh.creation.box(extents=[width, width, depth + 0.01])
    cut.apply_translation([0, 0, 0.03 - depth + 0.5 * (depth + 0.01)])
    return _block_with_pocket(cut)


def _peg(radius: float, length: float = 0.03) -> trimesh.Trimesh:
    return trimesh.creation.cylinder(radius=radius, height=length, sections=64)  # centred on its axis


def _key(width: float, length: float = 0.03) -> trimesh.Trimesh:
    return trimesh.creation.box(extents=[width, width, length])


def _insert_depth(tmp_path: Path, holed, peg, depth: float, max_force: float = 20.0) -> float:
    """Drive ``peg`` down the hole axis (z) from 2 mm above the block; return how deep its tip went (metres).

    The holed part is fixed on a ground plane; both bodies are compounds of
    the parts' convex pieces loaded from their OBJ text with no collision
    margin, exactly as :meth:`PyBulletWorld._collision_shape` and
    :meth:`PyBulletWorld.spawn_part` do. The peg is pulled by a fixed
    constraint whose target descends 20 mm/s, capped at ``max_force`` newtons.
    """
    client = pybullet.connect(pybullet.DIRECT)
    try:
        pybullet.setGravity(0, 0, -9.81, physicsClientId=client)
        dt = 1.0 / 240.0
        pybullet.setTimeStep(dt, physicsClientId=client)
        plane = pybullet.createCollisionShape(pybullet.GEOM_PLANE, physicsClientId=client)
        pybullet.createMultiBody(0.0, plane, physicsClientId=client)

        def shape(part, name: str) -> int:
            obj = tmp_path / f"{name}_pieces.obj"
            obj.write_text(decompose(part, _FAST, cache_dir=tmp_path / "cache").obj())
            return pybullet.createCollisionShape(pybullet.GEOM_MESH, fileName=str(obj), physicsClientId=client)

        block = pybullet.createMultiBody(0.0, shape(holed, "holed"), -1, [0, 0, 0], physicsClientId=client)
        top = 0.03
        half = 0.5 * float(peg.mesh.extents[2])
        z0 = top + 0.002 + half  # peg centre: its tip 2 mm above the hole
        body = pybullet.createMultiBody(
            peg.mass,
            shape(peg, "peg"),
            -1,
            [0, 0, z0],
            baseInertialFramePosition=np.asarray(peg.center_of_mass).tolist(),
            physicsClientId=client,
        )
        for b in (block, body):
            pybullet.changeDynamics(b, -1, lateralFriction=0.3, collisionMargin=0.0, physicsClientId=client)
        cid = pybullet.createConstraint(
            body, -1, -1, -1, pybullet.JOINT_FIXED, [0, 0, 0], [0, 0, 0], [0, 0, z0], physicsClientId=client
        )
        goal = top - depth - 0.002 + half  # 2 mm past the bottom, so the peg presses on it
        for k in range(int(1.6 / dt)):
            z = max(goal, z0 - 0.02 * k * dt)
            pybullet.changeConstraint(cid, [0, 0, z], maxForce=max_force, physicsClientId=client)
            pybullet.stepSimulation(physicsClientId=client)
        pos, _ = pybullet.getBasePositionAndOrientation(body, physicsClientId=client)
        tip = pos[2] - float(np.asarray(peg.center_of_mass)[2]) - half  # PyBullet reports the COM frame
        return top - tip
    finally:
        pybullet.disconnect(client)


@pytest.mark.slow
def test_round_peg_enters_a_half_millimetre_clearance_hole_to_the_full_depth(tmp_path: Path) -> None:
    holed = _stl_part(tmp_path, "holed", _round_hole_block(0.0055))
    peg = _stl_part(tmp_path, "peg", _peg(0.005))
    assert decompose(holed, _FAST, cache_dir=tmp_path / "cache").method == "plane_split"
    depth = _insert_depth(tmp_path, holed, peg, depth=0.02)
    assert depth == pytest.approx(0.02, abs=0.001)


@pytest.mark.slow
def test_round_peg_does_not_enter_a_hole_smaller_than_itself(tmp_path: Path) -> None:
    holed = _stl_part(tmp_path, "tight", _round_hole_block(0.0045))
    peg = _stl_part(tmp_path, "peg", _peg(0.005))
    depth = _insert_depth(tmp_path, holed, peg, depth=0.02)
    assert depth < 0.001  # stopped on the rim (its tip at most 1 mm below the top face)


@pytest.mark.slow
def test_square_key_enters_a_slot_with_0_3_mm_clearance(tmp_path: Path) -> None:
    slotted = _stl_part(tmp_path, "slotted", _square_slot_block(0.0086))
    key = _stl_part(tmp_path, "key", _key(0.008))
    depth = _insert_depth(tmp_path, slotted, key, depth=0.02)
    assert depth == pytest.approx(0.02, abs=0.001)


def test_holed_block_pieces_match_the_mesh_to_a_tenth_of_a_millimetre(tmp_path: Path) -> None:
    part = _stl_part(tmp_path, "holed", _round_hole_block(0.0055))
    d = decompose(part, DecompositionSettings(samples=5000), cache=False)
    assert d.method == "plane_split" and len(d.pieces) > 4
    assert d.hausdorff < 1e-4 and d.protrusion < 1e-4 and d.uncovered < 1e-4 and d.volume_error < 1e-3
    # the hole stays open: points on a circle 0.4 mm inside the hole wall are in no piece
    t = np.linspace(0, 2 * np.pi, 90, endpoint=False)
    ring = np.column_stack([0.0051 * np.cos(t), 0.0051 * np.sin(t), np.full(90, 0.02)])
    for v in d.pieces:
        h = trimesh.convex.convex_hull(v)
        assert not h.contains(ring).any()
    # the measure can fail: the part's single convex hull fills the 5.5 mm hole
    h, p, v, u = fidelity([np.asarray(part.mesh.convex_hull.vertices)], part.mesh, samples=5000)
    assert p > 0.004 and h > 0.004 and v > 0.03 and u < 1e-6


def test_a_damaged_cache_file_is_rebuilt(tmp_path: Path) -> None:
    part = _stl_part(tmp_path, "holed", _round_hole_block(0.0055))
    settings = DecompositionSettings(samples=2000)
    cache = tmp_path / "cache"
    first = decompose(part, settings, cache_dir=cache)
    (path,) = cache.glob("*.npz")
    route._MEMO.clear()  # read the disk, not this process's memo
    again = decompose(part, settings, cache_dir=cache)
    assert again.cached and len(again.pieces) == len(first.pieces)
    for a, b in zip(again.pieces, first.pieces, strict=True):
        np.testing.assert_array_equal(a, b)
    path.write_bytes(path.read_bytes()[:200])  # a truncated file, as a killed writer would leave
    route._MEMO.clear()
    rebuilt = decompose(part, settings, cache_dir=cache)
    assert not rebuilt.cached and len(rebuilt.pieces) == len(first.pieces)
    route._MEMO.clear()
    assert decompose(part, settings, cache_dir=cache).cached  # and written back whole
