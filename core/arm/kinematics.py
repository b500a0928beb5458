"""Forward and inverse kinematics of serial arms in a URDF, with pinocchio.

Generic over URDFs (used by the Nextage and by :mod:`asmteach.plugins.robots.urdf_arm`).
An *arm* is a named chain of joints (root to tip) and a TCP frame (a URDF link).
Poses are world-frame 4x4 transforms: the URDF root is placed at
``T_world_base``. Configurations of an arm are ``(dof,)`` radians (metres for
prismatic joints) in chain order; joints outside the arm keep the values of the
full configuration held by :class:`Kinematics` (``q_full``).

IK is damped least squares on SE(3) (pinocchio's log map and its Jacobian)
with clamping to the joint limits, started from the seed, then from the
arm's home and then from random configurations (seeded generator) until one
converges. A failure returns the best residual and the reason; it never raises.
"""

from __future__ import annotations

import difflib
import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin
from pydantic import Field

from asmteach.core.arm.urdf_check import UrdfInfo, check_urdf
from asmteach.core.errors import UserError
from asmteach.core.interfaces import IKResult
from asmteach.core.models import StrictModel

__all__ = ["ArmChain", "IKSettings", "Kinematics", "flip_jaw"]

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


@dataclass
class _Reduced:
    model: pin.Model
    data: pin.Data
    fid: int
    key: tuple[float, ...]


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
        self._reduced: dict[str, _Reduced] = {}

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
    def _reduced_model(self, arm: str) -> _Reduced:
        """The arm alone (other joints locked at ``q_full``); rebuilt when a locked ancestor moves."""
        c = self.chain(arm)
        m = self.model
        ancestors = [j for j in list(m.supports[c.joint_ids[0]])[1:] if j not in c.joint_ids]
        key = tuple(float(self.q_full[m.joints[j].idx_q]) for j in ancestors)
        cached = self._reduced.get(arm)
        if cached is not None and cached.key == key:
            return cached
        lock = [j for j in range(1, m.njoints) if j not in c.joint_ids]
        rm = pin.buildReducedModel(m, lock, self.q_full)
        red = _Reduced(rm, rm.createData(), rm.getFrameId(c.tcp_frame), key)
        self._reduced[arm] = red
        return red

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
        res = self._solve(c, T, q_seed, rng)
        try_flip = self.settings.try_flipped if flipped is None else flipped
        if not res.success and try_flip:
            alt = self._solve(c, flip_jaw(T), q_seed, rng)
            if alt.success:
                alt.flipped = True
                return alt
        return res

    def _solve(self, c: ArmChain, T_world: np.ndarray, q_seed: np.ndarray | None, rng: np.random.Generator) -> IKResult:
        s = self.settings
        T_base = np.linalg.solve(self.T_world_base, T_world)
        red = self._reduced_model(c.name)
        # Reach check against the chain's first joint: a target beyond the sum of link offsets is hopeless.
        pin.forwardKinematics(self.model, self.data, self.q_full)
        shoulder = self.data.oMi[c.joint_ids[0]].translation
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
        s = self.settings
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

    # ------------------------------------------------------------ batch FK (for collision checking)
    def moving_joints(self, arm: str) -> list[int]:
        """Ids of the joints whose world pose depends on the arm's joints (chain and descendants)."""
        cache = self.__dict__.setdefault("_moving_cache", {})
        if arm not in cache:
            first = self.chain(arm).joint_ids[0]
            cache[arm] = [j for j in range(1, self.model.njoints) if first in list(self.model.supports[j])]
        return list(cache[arm])

    def _joint_plan(self, arm: str) -> tuple[list[np.ndarray], list[tuple]]:
        """Static joint poses at ``q_full`` and the arm's per-joint recipe, cached until ``q_full`` changes.

        Single-configuration collision queries (one per planner state) spent most
        of their time recomputing these.
        """
        key = self.q_full.tobytes()
        cache = self.__dict__.setdefault("_plan_cache", {})
        hit = cache.get(arm)
        if hit is not None and hit[0] == key:
            return hit[1], hit[2]
        c = self.chain(arm)
        m, d = self.model, self.data
        pin.forwardKinematics(m, d, self.q_full)
        static = [self.T_world_base @ d.oMi[j].homogeneous for j in range(m.njoints)]
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

    def batch_joint_poses(self, arm: str, qs: np.ndarray) -> tuple[dict[int, np.ndarray], list[np.ndarray]]:
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
