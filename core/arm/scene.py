"""The arm robot's planning scene: an immutable value answered by one shared kinematic state and checker.

:class:`ArmScene` values are cheap (a few dicts of arrays); the expensive
state (pinocchio's full configuration, the fcl objects of the obstacles and
held parts, the finger joints) lives once in a :class:`SceneBinding`, which
brings itself to a scene only when a query asks about a different one, and
then changes only what differs (an obstacle list is rebuilt when the scene's
obstacle tuple is another object, a held part when its :class:`Attachment`
is). So a planner may hold and query many scenes; querying the same one again
costs nothing extra.

Frames: world, z up, metres; configurations in radians.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from asmteach.core.errors import UserError
from asmteach.core.robot import Attachment, PlanningScene

if TYPE_CHECKING:
    from asmteach.core.arm.collision import CollisionChecker
    from asmteach.core.arm.kinematics import Kinematics
    from asmteach.core.arm.sim_gripper import GripperJoints
    from asmteach.core.interfaces import Obstacle

__all__ = ["ArmScene", "SceneBinding"]


class SceneBinding:
    """The robot's kinematic state and collision checker, brought to one :class:`ArmScene` at a time.

    ``grippers`` maps each arm to its gripper joints (their open values are the
    fingers of an empty hand).
    """

    def __init__(self, kin: Kinematics, checker: CollisionChecker, grippers: Mapping[str, GripperJoints]) -> None:
        self.kin, self.checker, self.grippers = kin, checker, dict(grippers)
        self.applied: ArmScene | None = None

    def invalidate(self) -> None:
        """Forget the scene applied last (call after changing the checker or the kinematics directly)."""
        self.applied = None

    def set_fingers(self, arm: str, values: Sequence[float]) -> None:
        """Finger joint values of ``arm`` (metres or radians, as the URDF's finger joints) in ``q_full``."""
        m = self.kin.model
        for jn, v in zip(self.grippers[arm].finger_joints, values, strict=True):
            self.kin.q_full[m.joints[m.getJointId(jn)].idx_q] = float(v)

    def checker_at(self, scene: ArmScene, arm: str) -> CollisionChecker:
        """The checker holding ``scene``, for a query about ``arm`` (:class:`UserError` if there is no such arm)."""
        if arm not in self.grippers:
            raise UserError(f"unknown arm {arm!r}; this robot has {list(self.grippers)}")
        last = self.applied
        if scene is last:
            return self.checker
        if last is None or scene.obstacles is not last.obstacles:
            self.checker.set_obstacles(scene.obstacles)
        for a, gripper in self.grippers.items():
            q = scene.configuration.get(a)
            if q is not None and (last is None or not np.array_equal(q, last.configuration.get(a, q[:0]))):
                self.kin.set_arm(a, q)
            held = scene.attached.get(a)
            if last is None or held is not last.attached.get(a):
                self.checker.attach(a, None if held is None else held.part, None if held is None else held.T_tcp_part)
                opened = np.asarray(gripper.open_values, float)
                # each finger's inner face sits half the opening from the TCP (as in the simulator and the re-check)
                closed = held is not None and held.width is not None
                self.set_fingers(a, np.minimum(opened, 0.5 * held.width) if closed else opened)
        self.applied = scene
        return self.checker


class ArmScene(PlanningScene):
    """A :class:`~asmteach.core.robot.PlanningScene` of an arm robot; the table is the robot's own."""

    def __init__(
        self,
        binding: SceneBinding,
        configuration: Mapping[str, np.ndarray],
        obstacles: Sequence[Obstacle] = (),
        attached: Mapping[str, Attachment] | None = None,
        *,
        table: Obstacle | None = None,
    ) -> None:
        super().__init__(configuration, obstacles, attached)
        self._binding = binding
        self._table = table

    @property
    def table(self) -> Obstacle | None:
        return self._table

    def in_collision(self, arm: str, qs: np.ndarray, *, ignore: Sequence[str] = ()) -> np.ndarray:
        return self._binding.checker_at(self, arm).in_collision(arm, qs, ignore=ignore)

    def clearance(self, arm: str, qs: np.ndarray, upto: float = np.inf) -> np.ndarray:
        return self._binding.checker_at(self, arm).clearance(arm, qs, upto)

    def collision_report(self, arm: str, q: np.ndarray) -> list[tuple[str, str]]:
        return self._binding.checker_at(self, arm).report(arm, q)

    def collision_reports(self, arm: str, qs: np.ndarray) -> list[list[tuple[str, str]]]:
        return self._binding.checker_at(self, arm).reports(arm, qs)
