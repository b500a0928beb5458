"""Independent re-check of a whole plan with PyBullet contact queries.

The planners check their motions with this project's own collision model
(pinocchio kinematics, python-fcl geometry). The re-check
(:func:`~asmteach.core.arm.plan_checker.recheck_plan`; this module holds its rules
and results) replays a :class:`~asmteach.core.models.Plan` kinematically in a
separate PyBullet DIRECT client instead: PyBullet's own forward kinematics of the same URDF
(``resetJointState``), the table and parts spawned by
:class:`~asmteach.core.arm.sim.PyBulletWorld` with the collision
shapes execution uses, and Bullet's narrow phase (``getClosestPoints``). No
physics is stepped.

Replay: both arms start at ``home``; a trajectory moves its joints along
straight joint-space lines between waypoints (as execution interpolates them);
a ``close`` gripper event sets the fingers to half the grasp width each and,
with ``attach``, welds that part to the arm's TCP (``T_tcp_part`` fixed at the
moment of closing); an ``open`` event opens the fingers and leaves the part
where it is (lowered onto the table when let go within
:data:`~asmteach.core.arm.plan_checker.DROP_GAP` of it,
as gravity does), an obstacle from then on.

Densification: between two checked configurations no point of the robot, nor
of a held part, moves more than ``resolution`` metres. For joint ``j`` let
``R_j`` bound the distance from its axis to any collision geometry it carries
(the chain of joint-origin distances, which are constant on rigid links, plus
each link's geometry radius, plus a held part's radius about its TCP). A point
then moves at most ``sum_j |dq_j| R_j`` on a joint-space line, which sets the
number of sub-steps of every waypoint interval.

What is checked at every configuration (signed distance, metres; negative is
penetration): every robot link against the table and every part; every held
part against the table, the other parts and the robot; every pair of robot
links except the same link, links joined by a joint and the ``skip_pairs``
(SRDF-disabled). Allowed contacts: the holding arm's hand links against the
part it holds; a held part against the table on ``close`` (it still lies
there), ``lift``, ``place`` and ``insert`` segments, and against the other parts
on ``close`` and ``insert`` (the intended contact of insertion); see
:data:`TOUCH_RULES`. Penetration deeper than ``tolerance`` (0.5 mm by default)
is a collision. Bullet's collision margins are set to zero in the checker's
world so that distances are geometric (a part lying on the table measures 0).

Parts keep the collision shapes execution gives them: a convex hull, or
PyBullet's V-HACD pieces for a concave part, so a tight hole is only as open
as its decomposition.

Frames: world, z up, metres; joint values in radians; times in seconds from
the start of their segment.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from asmteach.core.models import StrictModel

__all__ = [
    "OTHER_PARTS",
    "TOUCH_RULES",
    "CheckedArm",
    "PlanCheck",
    "PlanCollision",
    "densify_by_reach",
]

OTHER_PARTS = "<other parts>"
"""In :data:`TOUCH_RULES`: every part other than the held one."""

TOUCH_RULES: dict[str, tuple[str, ...]] = {
    "close": ("table", OTHER_PARTS),  # the part is still lying where it was: on the table or on a part
    "lift": ("table",),
    "place": ("table",),
    "insert": ("table", OTHER_PARTS),
}
"""What the held part may touch, by the first word of a segment's label."""


@dataclass(frozen=True)
class CheckedArm:
    """What the checker needs to know of one arm (names as in the URDF)."""

    joints: tuple[str, ...]
    tcp_link: str
    finger_joints: tuple[str, ...]
    open_values: tuple[float, ...]
    """Finger joint values of the open hand (metres; each finger's inner face is this far from the TCP)."""
    hand_links: tuple[str, ...]
    """Links that may touch the part this arm holds (gripper body, fingers)."""


class PlanCollision(StrictModel):
    """One colliding pair within one segment (aggregated over that segment's configurations)."""

    segment: int = Field(description="index in plan.segments")
    label: str
    time_s: float = Field(description="first configuration in contact, seconds from the segment's start")
    a: str = Field(description="robot link or part (the moving or held side when there is one)")
    b: str = Field(description="robot link, part or 'table'")
    penetration_m: float = Field(description="deepest penetration over the segment, metres (positive)")
    configurations: int = Field(description="checked configurations of the segment where the pair penetrates")


class PlanCheck(StrictModel):
    """Result of :func:`recheck_plan`; ``ok`` is True when no collision was found."""

    ok: bool
    resolution_m: float = Field(description="largest motion of any robot or held-part point between checks")
    tolerance_m: float = Field(description="penetration allowed before a contact counts as a collision")
    n_configurations_checked: int
    min_distance_m: float = Field(
        description="least signed distance of any checked, not allowed pair, metres; "
        "capped at the query distance (larger is better)"
    )
    closest: str | None = Field(None, description="segment and pair of min_distance_m")
    collisions: list[PlanCollision] = Field(default_factory=list)
    warnings: list[str] = Field(default_factory=list)
    seconds: float = Field(0.0, description="wall time of the check")

    def summary(self) -> str:
        """One line for logs and reports (mm)."""
        head = (
            f"{'collision-free' if self.ok else f'{len(self.collisions)} collisions'}; "
            f"{self.n_configurations_checked} configurations at {self.resolution_m * 1000:.1f} mm; "
            f"min distance {self.min_distance_m * 1000:.1f} mm"
        )
        if self.collisions:
            c = max(self.collisions, key=lambda c: c.penetration_m)
            head += (
                f"; deepest: segment {c.segment} ({c.label}) {c.a} / {c.b} "
                f"{c.penetration_m * 1000:.1f} mm at {c.time_s:.2f} s"
            )
        return head


# ---------------------------------------------------------------- densification
def densify_by_reach(
    times: np.ndarray, positions: np.ndarray, reach: np.ndarray, resolution: float
) -> tuple[np.ndarray, np.ndarray]:
    """Sub-sample a piecewise-linear joint path so that no point moves more than ``resolution``.

    Parameters
    ----------
    times : ``(n,)`` seconds of the waypoints.
    positions : ``(n, dof)`` waypoints, radians (metres for prismatic joints).
    reach : ``(dof,)`` metres a point may move per unit of each joint (the distance bound ``R_j``
        of a revolute joint; 1 for a prismatic one).
    resolution : metres.

    Returns ``(times (m,), positions (m, dof))`` with every waypoint kept, linear in between.
    """
    q = np.atleast_2d(np.asarray(positions, dtype=float))
    t = np.asarray(times, dtype=float)
    if len(q) == 1:
        return t.copy(), q.copy()
    bound = np.abs(np.diff(q, axis=0)) @ np.asarray(reach, dtype=float)  # (n-1,) metres per interval
    steps = np.maximum(1, np.ceil(bound / resolution - 1e-9).astype(int))
    # fraction s in [0, 1) along each interval, then the last waypoint
    seg = np.repeat(np.arange(len(steps)), steps)
    s = (np.arange(len(seg)) - np.repeat(np.cumsum(steps) - steps, steps)) / np.repeat(steps, steps)
    dense_q = q[seg] + s[:, None] * (q[seg + 1] - q[seg])
    dense_t = t[seg] + s * (t[seg + 1] - t[seg])
    return np.append(dense_t, t[-1]), np.vstack([dense_q, q[-1]])
