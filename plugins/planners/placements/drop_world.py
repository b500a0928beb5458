"""The PyBullet world of the drop test: a plane and one part (its convex hull, its mass properties).

Drops tumble the part with light damping; releases are overdamped, so the part
goes where gravity takes it without momentum (a quasi-static release). See
:mod:`.drop_test` for what is dropped and how the rests are judged.
Metres, kilograms, seconds; rotations are ``R_world_link``.
"""

from __future__ import annotations

import numpy as np
import pybullet as pb
from scipy.spatial.transform import Rotation

__all__ = ["DropWorld"]

# Damping rates (1/s: PyBullet's multibody damping force is rate x momentum). Drops: light, so parts tumble
# and topple as they would. _HEAVY: overdamped, so a part goes where gravity takes it without momentum
# (a quasi-static release, what the margin d/h promises), while a balance on an edge still falls off
# (on a metre-sized part gravity grows a tilt at about (g / h) / _HEAVY = 1 / s).
_LIGHT_LINEAR, _LIGHT_ANGULAR = 0.04, 0.3
_HEAVY = 10.0


class DropWorld:
    """A PyBullet DIRECT world with a plane and one part (its hull, its mass properties)."""

    def __init__(
        self,
        hull_vertices: np.ndarray,
        com: np.ndarray,
        inertia: np.ndarray,
        *,
        friction: float,
        rolling_friction: float,
        time_step: float,
    ) -> None:
        self.client = pb.connect(pb.DIRECT)
        c = self.client
        pb.setGravity(0.0, 0.0, -9.81, physicsClientId=c)
        pb.setTimeStep(time_step, physicsClientId=c)
        plane = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=c)
        self.plane = pb.createMultiBody(0.0, plane, physicsClientId=c)
        # Link frame = principal axes at the COM (``p_part = com + E p_link``): PyBullet reports and sets
        # the pose of the inertial frame, which is then the link frame itself.
        evals, evecs = np.linalg.eigh(inertia)
        if np.linalg.det(evecs) < 0:
            evecs[:, 2] = -evecs[:, 2]
        self.E = evecs
        self.local = (np.asarray(hull_vertices, dtype=float) - com) @ evecs
        shape = pb.createCollisionShape(pb.GEOM_MESH, vertices=self.local.tolist(), physicsClientId=c)
        self.body = pb.createMultiBody(1.0, shape, basePosition=[0.0, 0.0, 1.0], physicsClientId=c)
        for b in (self.plane, self.body):
            # No rolling friction by default: it holds a polygon on its edges, where no rest is.
            pb.changeDynamics(
                b,
                -1,
                lateralFriction=friction,
                restitution=0.0,
                rollingFriction=rolling_friction,
                spinningFriction=0.0,
                physicsClientId=c,
            )
        pb.changeDynamics(
            self.body,
            -1,
            localInertiaDiagonal=np.maximum(evals, 1e-9).tolist(),
            linearDamping=_LIGHT_LINEAR,
            angularDamping=_LIGHT_ANGULAR,
            physicsClientId=c,
        )

    def close(self) -> None:
        pb.disconnect(self.client)

    def settle(
        self,
        R: np.ndarray,
        clearance: float,
        *,
        max_steps: int,
        window: int,
        still_deg: float,
        quasi_static: bool = False,
    ) -> tuple[np.ndarray, bool]:
        """Release the part with rotation ``R`` (part frame -> world), lowest point ``clearance`` m up.

        Returns the settled rotation (part frame -> world) and whether it came to rest: its
        part-frame down direction moved less than ``still_deg`` over the last ``window`` steps.
        Sliding or spinning about the vertical does not change where it rests, so only the down
        direction is watched (Bullet leaves flat contacts creeping by tenths of a millimetre).
        ``quasi_static``: first let it down heavily damped, so it comes to the rest gravity takes it
        to from there without rocking past it (what the margin ``d / h`` is about); then as a drop.
        """
        c = self.client
        self._place(R @ self.E, clearance)
        stride = max(1, window // 8)
        cos_still = np.cos(np.radians(still_deg))
        # Damped, a long part on a thin strip keeps trembling in place by about 0.1 degree per second
        # (Bullet's contact noise); rolling or falling off an edge is much faster than this.
        cos_damped = np.cos(np.radians(5.0 * still_deg))

        def run(steps: int, cos_still: float) -> bool:
            history: list[np.ndarray] = []
            for k in range(1, steps + 1):
                pb.stepSimulation(physicsClientId=c)
                if k % stride:
                    continue
                q = pb.getBasePositionAndOrientation(self.body, physicsClientId=c)[1]
                history.append(Rotation.from_quat(q).as_matrix()[2])  # -(link-frame down direction)
                if len(history) > 8 and min(float(h @ history[-9]) for h in history[-8:]) > cos_still:
                    return True
            return False

        def rest() -> bool:
            if run(max_steps, cos_still):
                return True
            # Still rolling (a cylinder on its side: neutral on a plane, and Bullet's solver keeps it going,
            # or rocks it on a thin strip): heavy damping turns the motion into a slow descent to a rest. A
            # balance on an edge still falls off (gravity beats this damping on a metre-sized part).
            self._damp(heavy=True)
            settled = run(2 * max_steps, cos_damped)
            self._damp(heavy=False)
            return settled

        if quasi_static:
            self._damp(heavy=True)
            run(2 * max_steps, cos_still)
            self._damp(heavy=False)
        settled = rest()
        if settled:
            # A nudge of 0.3 degrees: a rest takes the part back, a balance Bullet happened to stop in
            # (on a hull edge between two strips of a cylinder) lets it fall off.
            q = pb.getBasePositionAndOrientation(self.body, physicsClientId=c)[1]
            nudge = Rotation.from_rotvec(np.radians(0.3) * np.array([np.sqrt(0.5), np.sqrt(0.5), 0.0]))
            self._place((nudge * Rotation.from_quat(q)).as_matrix(), 1e-4 * float(np.ptp(self.local, axis=0).max()))
            # Let down heavily damped (undamped, a thin cylinder would start rolling again).
            self._damp(heavy=True)
            settled = run(max_steps, cos_damped)
            self._damp(heavy=False)
        q = pb.getBasePositionAndOrientation(self.body, physicsClientId=c)[1]
        return Rotation.from_quat(q).as_matrix() @ self.E.T, settled

    def _damp(self, *, heavy: bool) -> None:
        """Switch between the light damping of a drop and the overdamped quasi-static one."""
        lin, ang = (_HEAVY, _HEAVY) if heavy else (_LIGHT_LINEAR, _LIGHT_ANGULAR)
        pb.changeDynamics(self.body, -1, linearDamping=lin, angularDamping=ang, physicsClientId=self.client)

    def _place(self, R_link: np.ndarray, clearance: float) -> None:
        """Put the part at rest with rotation ``R_link`` (link frame -> world), lowest point ``clearance`` m up."""
        z = -float(np.min(self.local @ R_link[2])) + clearance
        pb.resetBasePositionAndOrientation(
            self.body, [0.0, 0.0, z], Rotation.from_matrix(R_link).as_quat().tolist(), physicsClientId=self.client
        )
        pb.resetBaseVelocity(self.body, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], physicsClientId=self.client)
