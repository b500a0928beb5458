"""OMPL 2 joint space built from python callables: bounds, validity, motion checks, paths.

A :class:`JointSpace` wraps an ``ompl.base.RealVectorStateSpace`` bounded by the
joint limits (radians) and an ``ompl.base.SpaceInformation`` whose state validity
checker calls the user's ``is_valid(q)``. Motion validation is OMPL's default
discrete motion validator (``si.checkMotion``): it checks states along the
straight joint-space segment every ``resolution`` radians (Euclidean joint-space
distance). States are created with ``si.allocState()`` (OMPL 2 has no
``ScopedState`` in python).

OMPL 2.0.1 python facts this module relies on (checked in the project venv):

- ``si.setStateValidityChecker(callable)`` accepts a python callable; it must
  return a python ``bool`` (a ``numpy.bool_`` raises ``std::bad_cast``);
  exceptions raised inside it propagate out of ``isValid``/``checkMotion``.
- Python subclasses of ``ob.StateCostIntegralObjective`` are not called back
  (no trampoline): ``stateCost`` overrides are silently ignored. Cost-aware
  simplification therefore works through the validity checker instead: a cost
  ceiling turns states above it invalid (see :meth:`JointSpace.cost_ceiling`).
- ``ompl.util.RNG.setSeed`` re-seeds the global seed generator even after
  samplers exist (it logs an error but the sequence restarts), so seeding before
  allocating samplers/planners makes each query reproducible.
- OMPL's ``NearestNeighbors`` structures are not bound; planners here use numpy.
"""

from __future__ import annotations

import contextlib
import itertools
from collections.abc import Callable, Iterator

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from asmteach.core.errors import UserError

__all__ = ["JointSpace", "quiet_ompl", "seed_ompl"]


@contextlib.contextmanager
def quiet_ompl(level: ou.LogLevel = ou.LOG_ERROR) -> Iterator[None]:
    """Lower OMPL's console logging for the duration of a block, then restore it."""
    previous = ou.getLogLevel()
    ou.setLogLevel(level)
    try:
        yield
    finally:
        ou.setLogLevel(previous)


def seed_ompl(seed: int) -> None:
    """Seed OMPL's global RNG seed generator (restarts its sequence; OMPL's warning silenced).

    OMPL treats seed 0 as "pick one at random", so seeds are mapped into ``1..2**31-1``.
    Call it after building the :class:`JointSpace` (its ``setup`` consumes seeds
    too) and right before allocating samplers, planners and simplifiers.
    """
    with quiet_ompl(ou.LOG_NONE):
        ou.RNG.setSeed(int(seed) % (2**31 - 1) + 1)


class JointSpace:
    """A bounded joint space with validity and motion checking through OMPL.

    Parameters
    ----------
    lower, upper : ``(dof,)`` joint limits, radians (``lower < upper``).
    is_valid : ``is_valid(q) -> bool`` for a ``(dof,)`` configuration; True when collision-free.
    resolution : joint-space step (radians, Euclidean norm over joints) at which
        motions are checked.
    """

    def __init__(
        self,
        lower: np.ndarray,
        upper: np.ndarray,
        is_valid: Callable[[np.ndarray], bool],
        *,
        resolution: float = 0.01,
    ) -> None:
        lo = np.asarray(lower, dtype=float).reshape(-1)
        hi = np.asarray(upper, dtype=float).reshape(-1)
        if lo.shape != hi.shape or lo.size == 0:
            raise UserError(f"joint limits: lower {lo.shape} and upper {hi.shape} must be equal non-empty vectors")
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo < hi)):
            raise UserError("joint limits: need finite lower < upper for every joint; fix the robot's limits")
        if not resolution > 0:
            raise UserError(f"collision_resolution must be > 0 radians (got {resolution})")
        self.dof = int(lo.size)
        self.lower = lo
        self.upper = hi
        self._user_valid = is_valid
        self._cost: Callable[[np.ndarray], float] | None = None
        self._ceiling = np.inf
        self.n_checks = 0
        """Number of calls to ``is_valid`` made through OMPL (state and motion checks)."""

        self.space = ob.RealVectorStateSpace(self.dof)
        bounds = ob.RealVectorBounds(self.dof)
        for i in range(self.dof):
            bounds.setLow(i, float(lo[i]))
            bounds.setHigh(i, float(hi[i]))
        self.space.setBounds(bounds)
        self.si = ob.SpaceInformation(self.space)
        self.si.setStateValidityChecker(self._check_state)
        # OMPL's resolution is a fraction of the space's maximum extent (Euclidean diagonal).
        fraction = min(1.0, float(resolution) / self.space.getMaximumExtent())
        self.si.setStateValidityCheckingResolution(fraction)
        self.si.setup()
        self.resolution = float(resolution)

    # ---------------------------------------------------------------- conversions
    def to_state(self, q: np.ndarray) -> ob.State:
        """A new OMPL state holding ``q`` (radians)."""
        state = self.si.allocState()
        self.space.copyFromReals(state, np.asarray(q, dtype=float).tolist())
        return state

    def to_numpy(self, state: ob.State) -> np.ndarray:
        """The ``(dof,)`` joint vector of an OMPL state."""
        return np.fromiter((state[i] for i in range(self.dof)), dtype=float, count=self.dof)

    def to_path(self, path: np.ndarray) -> og.PathGeometric:
        """An ``og.PathGeometric`` through the rows of ``path`` ``(n, dof)``."""
        return og.PathGeometric(self.si, [self.to_state(q) for q in np.asarray(path, dtype=float)])

    def from_path(self, path: og.PathGeometric) -> np.ndarray:
        """``(n, dof)`` waypoints of an OMPL geometric path."""
        return np.array([self.to_numpy(s) for s in path.getStates()], dtype=float).reshape(-1, self.dof)

    # ---------------------------------------------------------------- checks
    def _check_state(self, state: ob.State) -> bool:
        self.n_checks += 1
        q = self.to_numpy(state)
        if not bool(self._user_valid(q)):
            return False
        if self._cost is not None and np.isfinite(self._ceiling):
            return bool(self._cost(q) <= self._ceiling)
        return True

    def in_bounds(self, q: np.ndarray) -> bool:
        """True when every joint of ``q`` is within the limits."""
        q = np.asarray(q, dtype=float)
        return bool(np.all(q >= self.lower) and np.all(q <= self.upper))

    def is_valid(self, q: np.ndarray) -> bool:
        """Bounds and validity (and the cost ceiling, when one is active) of one configuration."""
        return self.in_bounds(q) and bool(self.si.isValid(self.to_state(q)))

    def check_motion(self, qa: np.ndarray, qb: np.ndarray) -> bool:
        """OMPL's discrete check of the straight segment ``qa -> qb`` (``qa`` assumed valid)."""
        return bool(self.si.checkMotion(self.to_state(qa), self.to_state(qb)))

    def check_path(self, path: np.ndarray) -> bool:
        """Every state and every segment of ``path`` ``(n, dof)`` valid at the space's resolution."""
        pts = np.asarray(path, dtype=float)
        if not all(self.in_bounds(q) for q in pts) or not self.is_valid(pts[0]):
            return False
        return all(self.check_motion(a, b) for a, b in itertools.pairwise(pts))

    @contextlib.contextmanager
    def cost_ceiling(self, cost: Callable[[np.ndarray], float], ceiling: float) -> Iterator[None]:
        """Treat states with ``cost(q) > ceiling`` as invalid inside the block.

        This is how OMPL's (cost-blind) path simplifier is kept from shortcutting
        through regions costlier than the worst state of a T-RRT path.
        """
        self._cost, self._ceiling = cost, float(ceiling)
        try:
            yield
        finally:
            self._cost, self._ceiling = None, np.inf

    # ---------------------------------------------------------------- sampling and simplification
    def sampler(self) -> Callable[[], np.ndarray]:
        """A function drawing uniform configurations with OMPL's state sampler (OMPL's seeded RNG)."""
        sampler = self.si.allocStateSampler()
        state = self.si.allocState()

        def draw() -> np.ndarray:
            sampler.sampleUniform(state)
            return self.to_numpy(state)

        return draw

    def simplify(
        self,
        path: np.ndarray,
        *,
        max_time: float | None = None,
        cost: Callable[[np.ndarray], float] | None = None,
        ceiling: float | None = None,
    ) -> np.ndarray:
        """Shorten ``path`` ``(n, dof)`` with OMPL's ``og.PathSimplifier``.

        ``max_time=None`` runs ``simplifyMax`` (until no change; deterministic);
        otherwise ``simplify`` stops after ``max_time`` seconds. With ``cost`` and
        ``ceiling``, new shortcuts must stay at or below that cost (OMPL's
        simplifier itself is cost-blind). The result keeps the end points and is
        re-checked for validity at the space's resolution; if it fails, the input
        is returned unchanged.
        """
        pts = np.asarray(path, dtype=float)
        if len(pts) < 3:
            return pts.copy()
        ompl_path = self.to_path(pts)
        simplifier = og.PathSimplifier(self.si)
        guard = (
            self.cost_ceiling(cost, ceiling) if cost is not None and ceiling is not None else contextlib.nullcontext()
        )
        with quiet_ompl(), guard:
            if max_time is None:
                simplifier.simplifyMax(ompl_path)
            else:
                simplifier.simplify(ompl_path, float(max_time))
        out = self.from_path(ompl_path)
        if not (np.allclose(out[0], pts[0]) and np.allclose(out[-1], pts[-1]) and self.check_path(out)):
            return pts.copy()
        return out
