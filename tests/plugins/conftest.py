"""Fixtures shared by the plugin tests of more than one package."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from asmteach.core.interfaces import AssemblyResult, PartModel


@dataclass
class PlannedPegInHole:
    """Set 1's peg-in-hole planned once (RRTConnect, seed 0) on the simulated Nextage; poses in metres."""

    task: Any
    a: PartModel
    b: PartModel
    T_a: np.ndarray
    T_b: np.ndarray
    robot: Any
    result: AssemblyResult


@pytest.fixture(scope="session")
def peg_in_hole_plan() -> Iterator[PlannedPegInHole]:
    """A whole two-part plan: A lying flat, B standing on its shank, so a grasp of B's head serves
    both the pick and the insertion. Planned once per session for every test that inspects it."""
    from asmteach.core import registry
    from asmteach.core.geometry import compose, from_rpy, rot_z
    from asmteach.core.interfaces import AssemblyProblem
    from asmteach.core.models import TablePlane
    from asmteach.core.parts import build_part, load_structure
    from asmteach.core.rests.placements import compute_placements

    task = load_structure("configs/parts/set1/peg_in_hole.yaml")
    a, b = build_part(task.part_a), build_part(task.part_b)
    robot = registry.create("robots", "nextage_pybullet", {"ik": {"max_starts": 4}}, seed=0)
    grasp_planner = registry.create("grasp_planners", "antipodal", {}, seed=0)
    motion = registry.create("motion_planners", "rrtconnect", {}, seed=0)
    planner = registry.create("assembly_planners", "regrasp", {}, seed=0)
    pa, pb = compute_placements(a), compute_placements(b)
    T_a = compose(from_rpy(0, 0, 0, t=[0.33, 0.22, 0.0]), rot_z(0.5), pa[0].T_table_part)
    upright = next(p for p in pb if p.T_table_part[2, 2] > 0.99)
    T_b = compose(from_rpy(0, 0, 0, t=[0.36, -0.22, 0.0]), rot_z(-0.3), upright.T_table_part)
    problem = AssemblyProblem(
        a,
        b,
        task,
        T_a,
        T_b,
        grasp_planner.plan(a, robot.hand),
        grasp_planner.plan(b, robot.hand),
        TablePlane(height=0.0),
    )
    result = planner.plan(problem, robot, motion)
    try:
        yield PlannedPegInHole(task, a, b, T_a, T_b, robot, result)
    finally:
        robot.close()
