"""A jig holding part A while B goes in, as a user's fixture would.

The planner says whether A, resting at its goal, stays put under B's insertion
(:func:`asmteach.core.rests.insertion_load.insertion_stability` at the guarded insertion's force limit; the
plan's ``stats["a_under_insertion"]``). Where it would slide or tip, a cell clamps it; ``execution.fixture``
says when:

- ``auto``: a jig when the plan says A does not resist the insertion;
- ``always``: a jig for every insertion;
- ``never``: no jig; the run goes on and the trace shows A pushed (if it is).

The simulated jig is a fixed constraint from A, where it stands when B's insertion begins, to the world.
A run that relies on one says so (:func:`jig_decision`'s note in the execute stage and the report's
header): the user must clamp A the same way in the real cell. Frames: world; metres, newtons.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import pybullet

from asmteach.core.arm.sim import PyBulletWorld

__all__ = ["FixtureMode", "JigDecision", "clamp_part", "jig_decision", "jig_key"]

FixtureMode = Literal["auto", "never", "always"]


@dataclass(frozen=True)
class JigDecision:
    """Whether A is held by a jig during B's insertion (``hold``), and the line the report shows (``note``)."""

    hold: bool
    note: str


def jig_decision(mode: FixtureMode, part: str, load: dict[str, Any] | None) -> JigDecision:
    """Decide the jig for ``part`` (A) from ``mode`` and the plan's ``load`` (``stats["a_under_insertion"]``:
    ``holds`` and a ``summary``; None when the planner did not check it)."""
    says = f": at its goal it {load['summary']}" if load and load.get("summary") else ""
    if mode == "always":
        return JigDecision(True, f"{part} held by a jig during the insertion (execution.fixture: always){says}")
    if load is None:
        return JigDecision(False, f"{part} not held: the planner did not check whether it resists the insertion")
    if load.get("holds", True):
        return JigDecision(False, "")
    if mode == "never":
        return JigDecision(False, f"{part} not held although it may move (execution.fixture: never){says}")
    return JigDecision(True, f"{part} held by a jig during the insertion{says}")


def jig_key(part: str) -> str:
    """The key of a part's jig among a :class:`PyBulletWorld`'s constraints (never an arm's name)."""
    return f"jig:{part}"


def clamp_part(robot: Any, part: str) -> bool:
    """Fix ``part`` to the world where it stands now, in ``robot``'s simulated world (``robot.sim``, a
    :class:`PyBulletWorld`); False when the robot has none (a real cell: the user clamps it). The constraint is
    one of the world's ``constraints``, so :meth:`PyBulletWorld.reset_world` removes it with the grasps."""
    world = getattr(robot, "sim", None)
    if not isinstance(world, PyBulletWorld):
        return False
    key = jig_key(part)
    if key in world.constraints:
        return True
    body, _ = world.parts[part]
    pos, orn = world.p.getBasePositionAndOrientation(body)
    cid = world.p.createConstraint(
        body, -1, -1, -1, pybullet.JOINT_FIXED, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], pos, childFrameOrientation=orn
    )
    # far above what the guarded insertion pushes (20 N): the jig, not the table's friction, holds A
    world.p.changeConstraint(cid, maxForce=1000.0)
    world.constraints[key] = (cid, part)
    return True
