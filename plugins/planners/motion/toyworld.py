"""Joint-space toy worlds: a point robot among boxes and spheres, for tests and benchmarks.

Obstacles live directly in joint space (radians), so validity and clearance
are exact and cheap: ``clearance(q)`` is the Euclidean signed distance from the
configuration to the nearest obstacle (negative inside). :func:`narrow_passage`
builds the classic wall-with-a-hole world in any dimension.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Box", "JointWorld", "Sphere", "clutter6d", "narrow_passage"]


@dataclass(frozen=True)
class Box:
    """Axis-aligned box: ``center`` and ``half`` extents, ``(dof,)`` radians."""

    center: np.ndarray
    half: np.ndarray

    def signed_distance(self, qs: np.ndarray) -> np.ndarray:
        """``(n,)`` signed distance of ``(n, dof)`` configurations (negative inside)."""
        d = np.abs(qs - self.center) - self.half
        outside = np.linalg.norm(np.maximum(d, 0.0), axis=1)
        inside = np.minimum(d.max(axis=1), 0.0)
        return outside + inside


@dataclass(frozen=True)
class Sphere:
    """Ball of ``radius`` (radians) around ``center`` ``(dof,)``."""

    center: np.ndarray
    radius: float

    def signed_distance(self, qs: np.ndarray) -> np.ndarray:
        """``(n,)`` signed distance of ``(n, dof)`` configurations (negative inside)."""
        return np.linalg.norm(qs - self.center, axis=1) - self.radius


@dataclass
class JointWorld:
    """Obstacles in a box-bounded joint space; the robot is the point ``q``."""

    lower: np.ndarray
    upper: np.ndarray
    obstacles: list[Box | Sphere] = field(default_factory=list)
    margin: float = 0.0
    """Configurations closer than this (radians) to an obstacle count as collisions."""

    @property
    def dof(self) -> int:
        return int(np.asarray(self.lower).size)

    def __post_init__(self) -> None:
        self.lower = np.asarray(self.lower, dtype=float)
        self.upper = np.asarray(self.upper, dtype=float)
        # Stacked per obstacle type so one query is a few vectorised numpy calls.
        boxes = [o for o in self.obstacles if isinstance(o, Box)]
        spheres = [o for o in self.obstacles if isinstance(o, Sphere)]
        self._box_c = np.array([b.center for b in boxes], dtype=float).reshape(-1, self.dof)
        self._box_h = np.array([b.half for b in boxes], dtype=float).reshape(-1, self.dof)
        self._sph_c = np.array([b.center for b in spheres], dtype=float).reshape(-1, self.dof)
        self._sph_r = np.array([b.radius for b in spheres], dtype=float)

    def clearance_batch(self, qs: np.ndarray) -> np.ndarray:
        """``(n,)`` distance to the nearest obstacle for ``(n, dof)`` configurations (inf if none)."""
        qs = np.atleast_2d(np.asarray(qs, dtype=float))
        best = np.full(len(qs), np.inf)
        if len(self._box_c):
            d = np.abs(qs[:, None, :] - self._box_c[None]) - self._box_h[None]
            sd = np.linalg.norm(np.maximum(d, 0.0), axis=2) + np.minimum(d.max(axis=2), 0.0)
            best = np.minimum(best, sd.min(axis=1))
        if len(self._sph_c):
            sd = np.linalg.norm(qs[:, None, :] - self._sph_c[None], axis=2) - self._sph_r[None]
            best = np.minimum(best, sd.min(axis=1))
        return best

    def clearance(self, q: np.ndarray) -> float:
        """Distance of one configuration to the nearest obstacle."""
        return float(self.clearance_batch(q)[0])

    def valid_batch(self, qs: np.ndarray) -> np.ndarray:
        """``(n,)`` True where a configuration is inside the bounds and not colliding."""
        qs = np.atleast_2d(np.asarray(qs, dtype=float))
        inside = np.all((qs >= self.lower) & (qs <= self.upper), axis=1)
        return inside & (self.clearance_batch(qs) > self.margin)

    def is_valid(self, q: np.ndarray) -> bool:
        """Validity of one configuration, as a python bool (OMPL needs one)."""
        q = np.asarray(q, dtype=float)
        if (q < self.lower).any() or (q > self.upper).any():
            return False
        if self.margin > 0:
            return self.clearance(q) > self.margin
        # Fast exact test without distances: strictly inside any box or ball collides.
        if len(self._box_c) and (np.abs(q - self._box_c) < self._box_h).all(axis=1).any():
            return False
        if len(self._sph_c) and (np.einsum("ij,ij->i", q - self._sph_c, q - self._sph_c) < self._sph_r**2).any():
            return False
        return True

    def inverse_clearance(self, q: np.ndarray, floor: float = 1e-3) -> float:
        """The T-RRT cost map used by the assembly planner: ``1 / max(clearance, floor)``."""
        return 1.0 / max(self.clearance(q), floor)


def narrow_passage(dof: int, *, gap: float = 0.2, wall: float = 0.2, extent: float = np.pi) -> JointWorld:
    """A wall across joint 0 at ``q0 = 0`` with one square hole of width ``gap`` centred on the origin.

    Bounds are ``[-extent, extent]`` on every joint. The wall is ``wall`` thick;
    the hole is ``gap`` wide along every other joint, so the passage narrows as
    ``dof`` grows. Start/goal on opposite sides, e.g. ``q0 = -/+ extent / 2``.
    """
    if dof < 2:
        raise ValueError("narrow_passage needs dof >= 2")
    lower = -extent * np.ones(dof)
    upper = extent * np.ones(dof)
    obstacles: list[Box | Sphere] = []
    # The wall is made of 2 * (dof - 1) slabs, each blocking one side of the hole along one joint.
    for j in range(1, dof):
        for side in (-1.0, 1.0):
            lo = lower.copy()
            hi = upper.copy()
            lo[0], hi[0] = -wall / 2, wall / 2
            if side < 0:
                hi[j] = -gap / 2
            else:
                lo[j] = gap / 2
            obstacles.append(Box(center=(lo + hi) / 2, half=(hi - lo) / 2))
    return JointWorld(lower=lower, upper=upper, obstacles=obstacles)


def clutter6d(margin: float = 0.02) -> tuple[JointWorld, np.ndarray, np.ndarray]:
    """The 6-D benchmark problem: a wall with a 2.5 rad hole, a ball and a box; ``(world, start, goal)``.

    The straight line from start to goal hits the wall. ``margin`` (radians)
    pads the obstacles for planning, so paths checked every ``2 * margin`` stay
    clear of the unpadded obstacles.
    """
    base = narrow_passage(6, gap=2.5)
    obstacles = [
        *base.obstacles,
        Sphere(np.array([-0.8, -1.0, 1.0, 0.0, 0.0, 0.0]), 0.5),
        Box(np.full(6, 1.5), np.full(6, 0.3)),
    ]
    world = JointWorld(lower=base.lower, upper=base.upper, obstacles=obstacles, margin=margin)
    start = np.array([-1.5, -2.0, 0.0, 0.0, 0.0, 0.0])
    goal = np.array([1.5, -2.0, 0.5, -0.5, 0.0, 0.0])
    return world, start, goal
