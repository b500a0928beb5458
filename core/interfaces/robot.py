"""The robot role: :class:`Robot` (a :class:`~asmteach.core.robot.RobotModel` plugin with its planning scene),
with the values its kinematics and scene take and give (:class:`IKResult`, :class:`Obstacle`).

The contracts themselves (RobotModel, PlanningScene, World) are in :mod:`asmteach.core.robot`.
Frames: world, z up, metres; joint values in radians.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Self

import numpy as np
import trimesh

from asmteach.core.errors import UserError
from asmteach.core.interfaces.part_model import PartModel
from asmteach.core.interfaces.plugin import Plugin
from asmteach.core.models import Plan, TablePlane
from asmteach.core.robot import PlanningScene, RobotModel

__all__ = ["IKResult", "Obstacle", "Robot"]


# ---------------------------------------------------------------- robot
@dataclass
class IKResult:
    """Inverse kinematics outcome: ``q`` ``(dof,)`` radians when solved; ``residual_pos`` (metres) and
    ``residual_rot`` (radians) are the final TCP errors; ``reason`` says why it failed."""

    success: bool
    q: np.ndarray | None
    residual_pos: float = float("inf")
    residual_rot: float = float("inf")
    reason: str | None = None
    flipped: bool = False
    """True when the solution uses the other finger order of the symmetric jaw."""


@dataclass
class Obstacle:
    """A static collision object of the world: ``mesh`` (metres, its own frame) at ``T_world`` ``(4, 4)``."""

    name: str
    mesh: trimesh.Trimesh
    T_world: np.ndarray


class Robot(Plugin, RobotModel):
    """The robot the config's ``robot:`` section builds: a :class:`RobotModel` with its current planning scene.

    The contracts themselves are in :mod:`asmteach.core.robot`: planners need
    the :class:`RobotModel` and a :class:`PlanningScene` (:attr:`scene`); the
    pipeline also needs a :class:`World` to run in, so a robot plugin the
    pipeline can run subclasses both (``class MyRobot(Robot, World)``).
    Use as a context manager so a simulator is always closed::

        with registry.create("robots", "nextage_pybullet", settings) as robot:
            ...

    The methods below that change the scene (:meth:`set_obstacles`,
    :meth:`attach`, :meth:`set_configuration`) replace :attr:`scene` with a new
    value and never move the world; the queries ask :attr:`scene`. They are
    kept for planners written against one mutable robot; new code passes
    :class:`PlanningScene` values instead.
    """

    _scene: PlanningScene | None = None

    # -- the planning scene
    @property
    def scene(self) -> PlanningScene:
        """The robot's planning scene now: after a world reset, the arms at home, no obstacles, empty hands."""
        if self._scene is None:
            raise NotImplementedError(f"{type(self).__name__} keeps no planning scene (set self.scene when built)")
        return self._scene

    @scene.setter
    def scene(self, scene: PlanningScene) -> None:
        self._scene = scene

    def current(self, arm: str) -> np.ndarray:
        """Where ``arm`` is now ``(dof,)`` radians: for a robot that is also a :class:`World`, the world's
        measured joints (:meth:`World.current`); otherwise its configuration in :attr:`scene`."""
        return np.array(self.scene.configuration[arm], dtype=float)

    def set_configuration(self, arm: str, q: np.ndarray) -> None:
        """:attr:`scene` with ``arm`` at ``q`` ``(dof,)`` radians (within the joint limits); the world stays."""
        q = np.asarray(q, dtype=float)
        lo, hi = self.joint_limits(arm)
        if q.shape != lo.shape or np.any(q < lo - 1e-6) or np.any(q > hi + 1e-6):
            raise UserError(
                f"configuration {np.round(q, 4).tolist()} of arm {arm!r} is outside its joint limits "
                f"[{np.round(lo, 4).tolist()}, {np.round(hi, 4).tolist()}]"
            )
        self.scene = self.scene.with_configuration(arm, np.clip(q, lo, hi))

    def set_obstacles(self, obstacles: Sequence[Obstacle]) -> None:
        """:attr:`scene` with ``obstacles`` (the table is always there)."""
        self.scene = self.scene.with_obstacles(obstacles)

    def attach(
        self, arm: str, part: PartModel | None, T_tcp_part: np.ndarray | None = None, *, width: float | None = None
    ) -> None:
        """:attr:`scene` with ``part`` held by ``arm`` (see :meth:`PlanningScene.with_attached`)."""
        self.scene = self.scene.with_attached(arm, part, T_tcp_part, width=width)

    def in_collision(self, arm: str, qs: np.ndarray, *, ignore: Sequence[str] = ()) -> np.ndarray:
        """:meth:`PlanningScene.in_collision` of :attr:`scene`: ``(n, dof)`` -> ``(n,)`` bool."""
        return self.scene.in_collision(arm, qs, ignore=ignore)

    def clearance(self, arm: str, qs: np.ndarray, upto: float = np.inf) -> np.ndarray:
        """:meth:`PlanningScene.clearance` of :attr:`scene`: ``(n, dof)`` -> ``(n,)`` metres."""
        return self.scene.clearance(arm, qs, upto)

    def collision_report(self, arm: str, q: np.ndarray) -> list[tuple[str, str]]:
        """:meth:`PlanningScene.collision_report` of :attr:`scene`."""
        return self.scene.collision_report(arm, q)

    def collision_reports(self, arm: str, qs: np.ndarray) -> list[list[tuple[str, str]]]:
        """:meth:`PlanningScene.collision_reports` of :attr:`scene`."""
        return self.scene.collision_reports(arm, qs)

    # -- an independent check
    def verify_plan(
        self, plan: Plan, parts: dict[str, tuple[PartModel, np.ndarray]], table: TablePlane, resolution: float = 0.005
    ) -> Any:
        """Re-check ``plan`` with a collision model independent of the planner's.

        ``parts`` maps a part name to its model and start pose ``T_world_part``
        (metres); arms start at :meth:`home`; ``resolution`` is the largest
        motion (metres) of any robot or held-part point between checks. Returns
        a pydantic model with at least ``ok: bool``, ``collisions: list`` and
        ``summary() -> str``. Optional: :class:`NotImplementedError` when the
        robot has no second collision model (the run then skips the re-check).
        """
        raise NotImplementedError(f"{type(self).__name__} has no independent plan check")

    def close(self) -> None:
        """Release the simulator and any other resources."""

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
