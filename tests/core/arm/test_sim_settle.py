"""``PyBulletWorld.track`` settles until the arm reaches its goal or stalls short of it (no second-long waits).

A stand-in client moves one joint a share of its error per step, up to a wall it cannot pass (an arm pressing a
part against resistance): the settle must end soon after the joint stops, and must run on while it still moves.
"""

from __future__ import annotations

import numpy as np

from asmteach.core.arm import sim as sim_module
from asmteach.core.arm.sim import PyBulletWorld


class _Joint:
    """One servo: each step closes ``share`` of the error to its target, never past ``wall`` (radians)."""

    def __init__(self, wall: float, share: float = 0.5) -> None:
        self.q, self.target, self.wall, self.share, self.steps = 0.0, 0.0, wall, share, 0

    def setJointMotorControl2(self, robot: int, j: int, mode: int, targetPosition: float, **_: float) -> None:
        self.target = targetPosition

    def stepSimulation(self) -> None:
        self.steps += 1
        self.q = min(self.q + self.share * (self.target - self.q), self.wall)

    def getJointStates(self, robot: int, ids: list[int]) -> list[tuple[float]]:
        return [(self.q,)]


def _world(client: _Joint) -> PyBulletWorld:
    w = PyBulletWorld.__new__(PyBulletWorld)
    w.p, w.robot, w.joint_index = client, 0, {"j": 0}
    w.time_step, w.position_gain = 1.0 / 240.0, 1.0
    return w


def _track(client: _Joint, goal: float) -> np.ndarray:
    times, positions = np.array([0.0, 0.1]), np.array([[0.0], [goal]])
    return _world(client).track(["j"], times, positions, np.array([1.0]), np.array([10.0]), settle=1.0)


def test_a_joint_held_short_of_its_goal_stops_settling_once_it_stalls() -> None:
    blocked = _Joint(wall=0.05)
    q = _track(blocked, goal=0.1)
    moving_steps = 24  # the 0.1 s path at 240 Hz
    assert q[0] == 0.05
    assert blocked.steps <= moving_steps + sim_module.STALL_STEPS + 2  # not the 240 steps of a whole second


def test_a_free_joint_settles_to_its_goal_within_tolerance() -> None:
    slow = _Joint(wall=1.0, share=0.05)  # far from the goal at the path's end, still moving every step
    q = _track(slow, goal=0.1)
    assert abs(q[0] - 0.1) < 1e-4
    assert slow.steps > 24 + sim_module.STALL_STEPS
