"""Forward and inverse kinematics of serial arms in a URDF, with pinocchio.

Generic over URDFs (used by the Nextage and by :mod:`asmteach.plugins.robots.urdf_arm`).
An *arm* is a named chain of joints (root to tip) and a TCP frame (a URDF link).
Poses are world-frame 4x4 transforms: the URDF root is placed at
``T_world_base``. Configurations of an arm are ``(dof,)`` radians (metres for
prismatic joints) in chain order; joints outside the arm keep the values of the
full configuration held by :class:`Kinematics` (``q_full``).

IK (:meth:`Kinematics.ik`) is damped least squares on SE(3), solved by
:mod:`~asmteach.core.arm.dls_ik`; the vectorised joint poses that collision
checking needs come from :mod:`~asmteach.core.arm.joint_poses`.
"""

from __future__ import annotations

import difflib
import itertools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from asmteach.core.arm.dls_ik import DlsSolver, IKSettings, flip_jaw
from asmteach.core.arm.joint_poses import JointPoses
from asmteach.core.arm.urdf_check import UrdfInfo, check_urdf
from asmteach.core.errors import UserError
from asmteach.core.interfaces import IKResult

__all__ = ["ArmChain", "Kinematics"]


@dataclass
class ArmChain:
    """One arm: joint ids in the full model (root to tip), limits and the TCP frame."""

    name: str
    joint_names: list[str]
    tcp_frame: str
    joint_ids: list[int] = field(default_factory=list)
    idx_q: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    lower: np.ndarray = field(default_factory=lambda: np.zeros(0))
    upper: np.ndarray = field(default_factory=lambda: np.zeros(0))
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(0))
    home: np.ndarray = field(default_factory=lambda: np.zeros(0))
    reach: float = float("inf")

    @property
    def dof(self) -> int:
        return len(self.joint_names)


def _closest(name: str, choices: list[str]) -> str:
    hit = difflib.get_close_matches(name, choices, n=1)
    return f"; did you mean {hit[0]!r}?" if hit else ""


class Kinematics:
    """Pinocchio model of a URDF with named arms.

    Parameters
    ----------
    urdf : path of the URDF (checked with :func:`check_urdf` first).
    arms : ``name -> (joint names root to tip, TCP link name)``.
    T_world_base : ``(4, 4)`` pose of the URDF root in the world.
    settings : IK options.
    homes : optional ``name -> (dof,)`` home configuration per arm.
    """

    def __init__(
        self,
        urdf: str | Path,
        arms: dict[str, tuple[list[str], str]],
        T_world_base: np.ndarray,
        settings: IKSettings | None = None,
        homes: dict[str, np.ndarray] | None = None,
    ) -> None:
        self.info: UrdfInfo = check_urdf(urdf)
        self.urdf = Path(urdf)
        try:
            self.model = pin.buildModelFromUrdf(str(self.urdf))
        except Exception as exc:  # noqa: BLE001 - pinocchio raises plain RuntimeErrors
            raise UserError(f"{self.urdf}: pinocchio cannot load it ({exc})") from None
        self.data = self.model.createData()
        self.settings = settings or IKSettings()
        self.T_world_base = np.asarray(T_world_base, dtype=float)
        self.base_se3 = pin.SE3(self.T_world_base[:3, :3].copy(), self.T_world_base[:3, 3].copy())
        names = list(self.model.names)
        for jn in names[1:]:
            j = self.model.joints[self.model.getJointId(jn)]
            if j.nq != j.nv:
                raise UserError(
                    f"{self.urdf.name}: joint {jn!r} is continuous or multi-DOF; use a revolute joint with limits"
                )
        self.q_full = np.clip(np.zeros(self.model.nq), self.model.lowerPositionLimit, self.model.upperPositionLimit)
        self.arms: dict[str, ArmChain] = {}
        for arm, (jnames, tcp) in arms.items():
            self.arms[arm] = self._make_chain(arm, list(jnames), tcp, (homes or {}).get(arm))
        self._ik = DlsSolver(self)
        self._poses = JointPoses(self)

    # ------------------------------------------------------------ set-up
    def _make_chain(self, arm: str, jnames: list[str], tcp: str, home: np.ndarray | None) -> ArmChain:
        m = self.model
        known = [n for n in m.names[1:]]
        ids: list[int] = []
        for jn in jnames:
            if jn not in known:
                raise UserError(f"{self.urdf.name}: arm {arm!r}: no movable joint named {jn!r}{_closest(jn, known)}")
            ids.append(m.getJointId(jn))
        for a, b in itertools.pairwise(ids):
            if a not in list(m.supports[b]):
                raise UserError(
                    f"{self.urdf.name}: arm {arm!r}: joint {m.names[a]!r} is not an ancestor of "
                    f"{m.names[b]!r}; list the joints from the base to the tip"
                )
        if not m.existFrame(tcp):
            frames = [f.name for f in m.frames]
            raise UserError(f"{self.urdf.name}: arm {arm!r}: no link or frame named {tcp!r}{_closest(tcp, frames)}")
        fid = m.getFrameId(tcp)
        if ids[-1] not in list(m.supports[m.frames[fid].parentJoint]):
            raise UserError(f"{self.urdf.name}: arm {arm!r}: TCP {tcp!r} does not move with joint {jnames[-1]!r}")
        idx = np.array([m.joints[i].idx_q for i in ids], dtype=int)
        lower = m.lowerPositionLimit[idx].copy()
        upper = m.upperPositionLimit[idx].copy()
        vel = m.velocityLimit[idx].copy()
        if home is None:
            home = np.clip(np.zeros(len(ids)), lower, upper)
        home = np.asarray(home, dtype=float)
        chain = ArmChain(arm, jnames, tcp, ids, idx, lower, upper, vel, home)
        chain.reach = self._reach_bound(chain, fid)
        return chain

    def _reach_bound(self, chain: ArmChain, fid: int) -> float:
        """Upper bound of the distance from the first joint's origin to the TCP (sum of link offsets)."""
        m = self.model
        total = 0.0
        for jid in chain.joint_ids[1:]:
            total += float(np.linalg.norm(m.jointPlacements[jid].translation))
        # fixed offsets from the last chain joint to the TCP frame
        frame = m.frames[fid]
        pj = frame.parentJoint
        total += float(np.linalg.norm(frame.placement.translation))
        while pj != chain.joint_ids[-1] and pj > 0:
            total += float(np.linalg.norm(m.jointPlacements[pj].translation))
            pj = m.parents[pj]
        return total

    # ------------------------------------------------------------ state
    def chain(self, arm: str) -> ArmChain:
        """The arm's chain; :class:`UserError` for an unknown arm name."""
        if arm not in self.arms:
            raise UserError(f"unknown arm {arm!r}; this robot has {sorted(self.arms)}")
        return self.arms[arm]

    def check_limits(self, arm: str, q: np.ndarray, tol: float = 1e-6) -> np.ndarray:
        """``q`` as a float array, or :class:`UserError` naming the joint outside its limits."""
        c = self.chain(arm)
        qa = np.asarray(q, dtype=float)
        if qa.shape[-1] != c.dof:
            raise UserError(f"arm {arm!r} has {c.dof} joints {c.joint_names}; got {qa.shape[-1]} values")
        if not np.all(np.isfinite(qa)):
            raise UserError(f"arm {arm!r}: joint values must be finite")
        bad = (qa < c.lower - tol) | (qa > c.upper + tol)
        if np.any(bad):
            k = int(np.argwhere(bad)[0][-1])
            v = float(qa.reshape(-1, c.dof)[np.any(bad.reshape(-1, c.dof), axis=1)][0, k])
            raise UserError(
                f"arm {arm!r}: joint {c.joint_names[k]} = {v:.6f} rad is outside its limits "
                f"[{c.lower[k]:.6f}, {c.upper[k]:.6f}]"
            )
        return qa

    def set_arm(self, arm: str, q: np.ndarray) -> None:
        """Store the arm's configuration in ``q_full`` (used for the other arm and for collision checks)."""
        c = self.chain(arm)
        self.q_full[c.idx_q] = self.check_limits(arm, q)

    def get_arm(self, arm: str) -> np.ndarray:
        return self.q_full[self.chain(arm).idx_q].copy()

    def full_q(self, arm: str, q: np.ndarray) -> np.ndarray:
        """``q_full`` with the arm's joints set to ``q``."""
        qf = self.q_full.copy()
        qf[self.chain(arm).idx_q] = q
        return qf

    # ------------------------------------------------------------ FK
    def frame_pose(self, frame: str, q_full: np.ndarray | None = None) -> np.ndarray:
        """World pose of any URDF link/frame at ``q_full`` (default: the stored one)."""
        if not self.model.existFrame(frame):
            frames = [f.name for f in self.model.frames]
            raise UserError(f"{self.urdf.name}: no link or frame named {frame!r}{_closest(frame, frames)}")
        fid = self.model.getFrameId(frame)
        pin.framesForwardKinematics(self.model, self.data, self.q_full if q_full is None else q_full)
        return self.T_world_base @ self.data.oMf[fid].homogeneous

    def fk(self, arm: str, q: np.ndarray) -> np.ndarray:
        """``T_world_tcp`` of ``arm`` at ``q`` (other joints from ``q_full``)."""
        c = self.chain(arm)
        return self.frame_pose(c.tcp_frame, self.full_q(arm, self.check_limits(arm, q)))

    def jacobian(self, arm: str, q: np.ndarray) -> np.ndarray:
        """``(6, dof)`` TCP Jacobian, linear then angular, in world axes at the TCP origin."""
        c = self.chain(arm)
        qf = self.full_q(arm, np.asarray(q, dtype=float))
        fid = self.model.getFrameId(c.tcp_frame)
        J = pin.computeFrameJacobian(self.model, self.data, qf, fid, pin.LOCAL_WORLD_ALIGNED)[:, c.idx_q]
        R = self.T_world_base[:3, :3]
        return np.vstack([R @ J[:3], R @ J[3:]])

    # ------------------------------------------------------------ IK
    def ik(
        self,
        arm: str,
        T_world_tcp: np.ndarray,
        q_seed: np.ndarray | None = None,
        *,
        rng: np.random.Generator | None = None,
        flipped: bool | None = None,
    ) -> IKResult:
        """Solve ``fk(arm, q) == T_world_tcp`` within the joint limits; never raises on failure.

        ``flipped=None`` uses ``settings.try_flipped``: when the pose itself has
        no solution, the pose turned 180 deg about the TCP z axis (the other
        finger order of a symmetric jaw) is tried and ``IKResult.flipped`` says so.
        """
        try:
            c = self.chain(arm)
            T = np.asarray(T_world_tcp, dtype=float)
            if T.shape != (4, 4) or not np.all(np.isfinite(T)):
                return IKResult(False, None, reason="the target is not a finite 4x4 pose")
        except UserError as exc:
            return IKResult(False, None, reason=str(exc))
        rng = rng if rng is not None else np.random.default_rng(0)
        res = self._ik.solve(c, T, q_seed, rng)
        try_flip = self.settings.try_flipped if flipped is None else flipped
        if not res.success and try_flip:
            alt = self._ik.solve(c, flip_jaw(T), q_seed, rng)
            if alt.success:
                alt.flipped = True
                return alt
        return res

    # ------------------------------------------------------------ batch FK (for collision checking)
    def moving_joints(self, arm: str) -> list[int]:
        """Ids of the joints whose world pose depends on the arm's joints (chain and descendants)."""
        return self._poses.moving_joints(arm)

    def batch_joint_poses(self, arm: str, qs: np.ndarray) -> tuple[dict[int, np.ndarray], list[np.ndarray]]:
        """World poses of every joint frame for ``n`` arm configurations ``(n, dof)``; see
        :meth:`JointPoses.batch <asmteach.core.arm.joint_poses.JointPoses.batch>`."""
        return self._poses.batch(arm, qs)
