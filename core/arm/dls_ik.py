"""Damped-least-squares inverse kinematics of one arm of a :class:`~asmteach.core.arm.kinematics.Kinematics`.

IK is damped least squares on SE(3) (pinocchio's log map and its Jacobian)
with clamping to the joint limits, started from the seed, then from the
arm's home and then from random configurations (seeded generator) until one
converges. A failure returns the best residual and the reason; it never raises.
Poses are world-frame ``(4, 4)`` transforms; joint values radians (metres for
prismatic joints); residuals metres and radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin
from pydantic import Field

from asmteach.core.interfaces import IKResult
from asmteach.core.models import StrictModel

if TYPE_CHECKING:  # kinematics builds a DlsSolver; these names are only annotations here
    from asmteach.core.arm.kinematics import ArmChain, Kinematics

__all__ = ["FLIP_Z", "DlsSolver", "IKSettings", "flip_jaw"]

FLIP_Z = np.diag([-1.0, -1.0, 1.0, 1.0])
"""TCP rotated 180 deg about its z (approach) axis: the other finger order of a symmetric jaw."""


def flip_jaw(T_world_tcp: np.ndarray) -> np.ndarray:
    """The same grasp with the fingers swapped: ``T @ Rz(pi)``."""
    return np.asarray(T_world_tcp, dtype=float) @ FLIP_Z


class IKSettings(StrictModel):
    """Damped-least-squares IK options."""

    tol_pos: float = Field(1e-5, gt=0.0, description="position tolerance, metres")
    tol_rot: float = Field(1e-4, gt=0.0, description="orientation tolerance, radians")
    max_iters: int = Field(60, ge=1, description="iterations per start")
    max_starts: int = Field(40, ge=1, description="seed, home, then random starts")
    batch_starts: int = Field(
        4,
        ge=1,
        description="starts per target when many targets are solved at once (random ones only for "
        "targets that neither the seed nor the home reach)",
    )
    damping: float = Field(1e-6, gt=0.0, description="DLS damping lambda^2 (m^2)")
    max_step: float = Field(0.4, gt=0.0, description="largest joint step per iteration, radians")
    try_flipped: bool = Field(True, description="for grasps, also try the TCP turned 180 deg about z")


@dataclass
class _Reduced:
    model: pin.Model
    data: pin.Data
    fid: int
    key: tuple[float, ...]


class DlsSolver:
    """Damped-least-squares IK of ``kin``'s arms, each on the arm alone (other joints locked at ``kin.q_full``)."""

    def __init__(self, kin: Kinematics) -> None:
        self.kin = kin
        self._reduced: dict[str, _Reduced] = {}

    def reduced_model(self, arm: str) -> _Reduced:
        """The arm alone (other joints locked at ``q_full``); rebuilt when a locked ancestor moves."""
        c = self.kin.chain(arm)
        m = self.kin.model
        ancestors = [j for j in list(m.supports[c.joint_ids[0]])[1:] if j not in c.joint_ids]
        key = tuple(float(self.kin.q_full[m.joints[j].idx_q]) for j in ancestors)
        cached = self._reduced.get(arm)
        if cached is not None and cached.key == key:
            return cached
        lock = [j for j in range(1, m.njoints) if j not in c.joint_ids]
        rm = pin.buildReducedModel(m, lock, self.kin.q_full)
        red = _Reduced(rm, rm.createData(), rm.getFrameId(c.tcp_frame), key)
        self._reduced[arm] = red
        return red

    def solve(self, c: ArmChain, T_world: np.ndarray, q_seed: np.ndarray | None, rng: np.random.Generator) -> IKResult:
        s = self.kin.settings
        T_base = np.linalg.solve(self.kin.T_world_base, T_world)
        red = self.reduced_model(c.name)
        # Reach check against the chain's first joint: a target beyond the sum of link offsets is hopeless.
        pin.forwardKinematics(self.kin.model, self.kin.data, self.kin.q_full)
        shoulder = self.kin.data.oMi[c.joint_ids[0]].translation
        dist = float(np.linalg.norm(T_base[:3, 3] - shoulder))
        if dist > c.reach * 1.001:
            return IKResult(
                False,
                None,
                residual_pos=dist - c.reach,
                residual_rot=float("nan"),
                reason=f"target outside the workspace: {dist:.3f} m from the arm's first joint, "
                f"reach at most {c.reach:.3f} m",
            )
        oMdes = pin.SE3(T_base[:3, :3].copy(), T_base[:3, 3].copy())
        starts: list[np.ndarray] = []
        if q_seed is not None:
            starts.append(np.clip(np.asarray(q_seed, dtype=float), c.lower, c.upper))
        starts.append(c.home.copy())
        best: tuple[float, float, np.ndarray | None] = (float("inf"), float("inf"), None)
        for k in range(s.max_starts):
            q0 = starts[k] if k < len(starts) else rng.uniform(c.lower, c.upper)
            ok, q, ep, er = self._dls(red, oMdes, q0, c.lower, c.upper)
            if ok:
                return IKResult(True, q, residual_pos=ep, residual_rot=er)
            if ep + 0.1 * er < best[0] + 0.1 * best[1]:
                best = (ep, er, q)
        return IKResult(
            False,
            None,
            residual_pos=best[0],
            residual_rot=best[1],
            reason=f"no solution within the joint limits after {s.max_starts} starts "
            f"(best residual {best[0] * 1000:.2f} mm, {math.degrees(best[1]):.2f} deg)",
        )

    def _dls(
        self, red: _Reduced, oMdes: pin.SE3, q: np.ndarray, lower: np.ndarray, upper: np.ndarray
    ) -> tuple[bool, np.ndarray, float, float]:
        s = self.kin.settings
        rm, rd, fid = red.model, red.data, red.fid
        eye = np.eye(6) * s.damping
        ep = er = float("inf")
        for _ in range(s.max_iters):
            pin.forwardKinematics(rm, rd, q)
            oMf = pin.updateFramePlacement(rm, rd, fid)
            iMd = oMf.actInv(oMdes)
            err = pin.log6(iMd).vector  # in the TCP frame
            ep = float(np.linalg.norm(iMd.translation))
            er = float(np.linalg.norm(err[3:]))
            if ep < s.tol_pos and er < s.tol_rot:
                return True, q, ep, er
            J = pin.computeFrameJacobian(rm, rd, q, fid, pin.LOCAL)
            J = -pin.Jlog6(iMd.inverse()) @ J
            v = -J.T @ np.linalg.solve(J @ J.T + eye, err)
            n = float(np.max(np.abs(v)))
            if n > s.max_step:
                v *= s.max_step / n
            q = np.clip(q + v, lower, upper)
        return False, q, ep, er
