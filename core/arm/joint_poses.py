"""Joint poses of many arm configurations at once (vectorised forward kinematics, numpy), for collision checks.

Uses the joint placements and motion axes of a :class:`~asmteach.core.arm.kinematics.Kinematics`'
pinocchio model; poses are world-frame ``(4, 4)`` transforms (metres), joint values radians (metres for
prismatic joints).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

if TYPE_CHECKING:  # kinematics builds a JointPoses; the name is only an annotation here
    from asmteach.core.arm.kinematics import Kinematics

__all__ = ["JointPoses"]


class JointPoses:
    """Batched joint poses of ``kin``'s arms, with the static part cached until ``kin.q_full`` changes."""

    def __init__(self, kin: Kinematics) -> None:
        self.kin = kin
        self._moving: dict[str, list[int]] = {}
        self._plans: dict[str, tuple[bytes, list[np.ndarray], list[tuple]]] = {}

    def moving_joints(self, arm: str) -> list[int]:
        """Ids of the joints whose world pose depends on the arm's joints (chain and descendants)."""
        cache = self._moving
        if arm not in cache:
            first = self.kin.chain(arm).joint_ids[0]
            cache[arm] = [j for j in range(1, self.kin.model.njoints) if first in list(self.kin.model.supports[j])]
        return list(cache[arm])

    def _joint_plan(self, arm: str) -> tuple[list[np.ndarray], list[tuple]]:
        """Static joint poses at ``q_full`` and the arm's per-joint recipe, cached until ``q_full`` changes.

        Single-configuration collision queries (one per planner state) spent most
        of their time recomputing these.
        """
        key = self.kin.q_full.tobytes()
        cache = self._plans
        hit = cache.get(arm)
        if hit is not None and hit[0] == key:
            return hit[1], hit[2]
        c = self.kin.chain(arm)
        m, d = self.kin.model, self.kin.data
        pin.forwardKinematics(m, d, self.kin.q_full)
        static = [self.kin.T_world_base @ d.oMi[j].homogeneous for j in range(m.njoints)]
        steps = []
        for j in self.moving_joints(arm):
            parent = m.parents[j]
            M = m.jointPlacements[j].homogeneous
            if j in c.joint_ids:
                S = np.asarray(d.joints[j].S).reshape(6, -1)[:, 0]  # motion subspace: (linear, angular)
                steps.append((j, parent, M, S, c.joint_ids.index(j), None))
            else:
                # not an arm joint: its own displacement stays at q_full
                fixed = np.linalg.solve(M, np.linalg.solve(static[parent], static[j]))[None]
                steps.append((j, parent, M, None, -1, fixed))
        cache[arm] = (key, static, steps)
        return static, steps

    def batch(self, arm: str, qs: np.ndarray) -> tuple[dict[int, np.ndarray], list[np.ndarray]]:
        """World poses of every joint frame for ``n`` arm configurations, vectorised with numpy.

        Returns ``(moving, static)``: ``moving[j]`` is ``(n, 4, 4)`` for joints that
        move with the arm; ``static[j]`` is ``(4, 4)`` for every joint (at ``q_full``),
        index 0 being the URDF root. Uses the joint placements and motion axes of
        the pinocchio model; checked against pinocchio's FK in the tests.
        """
        qs = np.atleast_2d(np.asarray(qs, dtype=float))
        n = qs.shape[0]
        static, steps = self._joint_plan(arm)
        moving: dict[int, np.ndarray] = {}
        for j, parent, M, S, k, fixed in steps:
            T_parent = moving[parent] if parent in moving else np.broadcast_to(static[parent], (n, 4, 4))
            moving[j] = T_parent @ (M @ (_axis_motion(S, qs[:, k]) if S is not None else fixed))
        return moving, static


def _axis_motion(S: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``(n, 4, 4)`` joint displacements for a 1-DOF revolute (angular S) or prismatic (linear S) joint."""
    n = q.shape[0]
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    lin, ang = S[:3], S[3:]
    if np.linalg.norm(ang) > 0.5:
        k = ang / np.linalg.norm(ang)
        K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
        s, cth = np.sin(q)[:, None, None], np.cos(q)[:, None, None]
        T[:, :3, :3] = np.eye(3) + s * K + (1.0 - cth) * (K @ K)
    else:
        T[:, :3, 3] = q[:, None] * lin[None, :]
    return T
