"""Independent check of stable placements: drop the part onto a plane in PyBullet and see where it settles.

Two experiments on one part, both in a headless PyBullet world (z up, plane z = 0):

* **drops**: the part is released from ``drops`` seeded random orientations
  (uniform on SO(3)), its lowest point ``drop_height`` above the plane, and
  simulated until it comes to rest; the settled orientations are *rests*;
* **releases**: each reported placement is set on the plane, tilted by
  ``0.8 atan(min_margin)`` (4.6 degrees for the default ``d / h >= 0.1``:
  within what the margin promises to withstand) about each of
  ``directions`` horizontal axes, let down quasi-statically (heavily damped,
  so it does not rock past its rest: the margin is a static promise), then
  simulated as a drop; it *stays put* when every release settles back in it.
  A part on a curved side may instead roll along it (a cylinder's strips
  are a neutral family): a release that ends elsewhere with the COM at the
  same height (within 5 %) is *rolled*, one where the COM fell is
  *spurious*. Each rest the drops found on no reported placement is released the same
  way tilted by ``1.2 atan(min_margin)`` (6.9 degrees; with 8 axes the
  worst one is within 22.5 degrees of the nearest edge, so the tilt toward
  it is at least 6.3 degrees, past 5.7): when the part leaves it for some
  axis, the rest is *fragile*, as the rule says it is; when it keeps the
  part, the rest is robust and the planner *missed* it.

Collision shape: the convex hull of the mesh. Only the hull can touch a
plane (any point of the part that touches the plane is a point of the hull
on its supporting plane), so resting on a plane is the same for the part and
for its hull; the mass properties are the part's own (its COM and inertia,
uniform density).

Orientations are compared *up to a rotation about the vertical axis*: two
orientations differ only by a yaw exactly when they put the same part-frame
direction down, so the geodesic distance between the classes is the angle
between the down directions ``R^T (0, 0, -1)`` (part frame). Rests closer
than ``match_deg`` are one cluster (single linkage); a cluster matches the
nearest reported placement when that is within ``match_deg`` too.

Units: the part is scaled so its largest hull extent is at least ``size``
metres and its smallest width at least ``min_width`` before the simulation.
Resting is scale invariant (gravity and the margins ``d / h`` are), and a
large body keeps Bullet's collision margin and time step small against the
part.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from asmteach.core.rests.facets import convex_hull, is_closed
from asmteach.plugins.planners.placements.drop_world import DropWorld

__all__ = ["DropReport", "down_normal", "drop_test"]

_DOWN = np.array([0.0, 0.0, -1.0])


def down_normal(T_table_part: np.ndarray) -> np.ndarray:
    """Part-frame unit direction that points down (``-z`` of the table) at ``T_table_part``."""
    return np.asarray(T_table_part, dtype=float)[:3, :3].T @ _DOWN


@dataclass
class DropReport:
    """Where a part settled, against the reported placements (all normals part frame, unit).

    ``placement_normals``: down direction of each reported placement; ``rests``: ``(k, 3)`` down
    direction of each cluster of settled drops, with ``rest_counts`` drops each and ``rest_match`` the
    index of the matching placement (-1: none; -2: none, but a facet the planner refused on purpose);
    ``rest_stays``: a rest on no placement, released tilted just past the margin's angle, settled back
    in it for every tilt axis (True for matched rests). A rest on no placement is *missed* when it keeps
    the part so (a robust rest the planner lacks), *fragile* when the part leaves it (refusing it is
    what the margin rule is for). Per placement: ``stays``, the releases tilted just
    within the margin's angle all settled back in it; ``rolled``, they settled elsewhere at the same COM
    height (within 5 %) instead (a part on a curved side rolls along it: neutral); neither:
    *spurious*; ``release_error_deg``, the farthest they settled, degrees from the placement. ``unsettled``: drops still
    moving after the time allowed (twice ``max_seconds``, the second half heavily damped).
    """

    placement_normals: np.ndarray
    rests: np.ndarray
    rest_counts: np.ndarray
    rest_match: np.ndarray
    rest_stays: np.ndarray
    stays: np.ndarray
    rolled: np.ndarray
    release_error_deg: np.ndarray
    unsettled: int
    drops: int
    notes: list[str] = field(default_factory=list)

    @property
    def reported(self) -> int:
        """Number of reported placements."""
        return len(self.placement_normals)

    @property
    def found(self) -> int:
        """Number of distinct rests the drops settled in."""
        return len(self.rests)

    @property
    def matched(self) -> int:
        """Rests that match a reported placement."""
        return int(np.sum(self.rest_match >= 0))

    @property
    def missed(self) -> int:
        """Rests on no reported placement that hold the part even tilted past the margin's angle."""
        return int(np.sum((self.rest_match < 0) & self.rest_stays))

    @property
    def fragile(self) -> int:
        """Rests on no reported placement that the part leaves when tilted past the margin's angle."""
        return int(np.sum((self.rest_match < 0) & ~self.rest_stays))

    @property
    def below_margin(self) -> int:
        """Rests on facets the planner refused on purpose (given as ``refused_normals``)."""
        return int(np.sum(self.rest_match == -2))

    @property
    def spurious(self) -> int:
        """Reported placements that, released, left and toppled (the COM fell by more than 5 %)."""
        return int(np.sum(~self.stays & ~self.rolled))

    @property
    def rolled_away(self) -> int:
        """Reported placements that, released, rolled along a curved side (COM height kept within 5 %)."""
        return int(np.sum(self.rolled))

    @property
    def agrees(self) -> bool:
        """No missed rest and no spurious placement."""
        return self.missed == 0 and self.spurious == 0

    def summary(self) -> str:
        """One line: reported, found, matched, missed, spurious."""
        return (
            f"reported {self.reported}, rests {self.found} ({self.drops} drops, {self.unsettled} unsettled), "
            f"matched {self.matched}, missed {self.missed}, fragile {self.fragile} "
            f"({self.below_margin} on refused facets), spurious {self.spurious}, rolled {self.rolled_away}"
        )


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles (degrees) between unit rows of ``a`` (``(n, 3)``) and unit rows of ``b`` (``(m, 3)``): ``(n, m)``."""
    return np.degrees(np.arccos(np.clip(np.atleast_2d(a) @ np.atleast_2d(b).T, -1.0, 1.0)))


def _cluster(normals: np.ndarray, tol_deg: float) -> np.ndarray:
    """Single-linkage labels of unit ``normals`` joined when closer than ``tol_deg``."""
    n = len(normals)
    labels = np.arange(n)
    if n == 0:
        return labels
    close = _angle_deg(normals, normals) < tol_deg
    for i in range(n):  # a few hundred rests at most: plain label propagation
        for j in np.flatnonzero(close[i]):
            a, b = labels[i], labels[j]
            if a != b:
                labels[labels == max(a, b)] = min(a, b)
    return np.unique(labels, return_inverse=True)[1]


def drop_test(
    mesh: trimesh.Trimesh,
    placement_normals: np.ndarray,
    center_of_mass: np.ndarray | None = None,
    *,
    refused_normals: np.ndarray | None = None,
    drops: int = 30,
    seed: int = 0,
    min_margin: float = 0.1,
    directions: int = 8,
    match_deg: float = 2.5,
    drop_height: float = 0.02,
    friction: float = 0.8,
    rolling_friction: float = 0.0,
    size: float = 1.0,
    min_width: float = 0.5,
    time_step: float = 1.0 / 240.0,
    max_seconds: float = 8.0,
) -> DropReport:
    """Drop ``mesh`` and release it in each placement; compare where it settles with ``placement_normals``.

    Parameters
    ----------
    mesh : the part, part frame, metres (a non-watertight mesh takes its hull's mass properties).
    placement_normals : ``(P, 3)`` part-frame down direction of each reported placement
        (:func:`down_normal` of its ``T_table_part``).
    center_of_mass : part frame, metres; default the mesh's.
    refused_normals : ``(Q, 3)`` part-frame down directions the planner refused on purpose (facets that
        hold the COM with ``d / h`` below its margin); a rest matching none of the placements but one of
        these is labelled -2 in ``rest_match`` (missed or fragile is decided by releasing it).
    drops : random orientations dropped (seeded by ``seed``).
    min_margin : the margin ``d / h`` the placements claim. Each placement is released tilted by
        ``0.8 atan(min_margin)`` (4.6 degrees) about ``directions`` horizontal axes and must settle back
        in it (or roll into another reported placement); each rest on no placement is released tilted by
        ``1.2 atan(min_margin)`` and is *fragile* when the part leaves it for some axis.
    match_deg : rests closer than this (degrees between down directions) are one; a rest matches a
        placement within it.
    drop_height : clearance of the lowest point at release, as a fraction of the scaled part's size.
    size, min_width : the part is scaled so its largest extent is at least ``size`` and its smallest
        width at least ``min_width`` metres (Bullet rounds convex shapes by a few millimetres: a 5 mm
        strip of a thin cylinder's hull would roll like a true cylinder).
    """
    rng = np.random.default_rng(seed)
    hold_deg = 0.8 * float(np.degrees(np.arctan(min_margin)))
    leave_deg = 1.2 * float(np.degrees(np.arctan(min_margin)))
    hull = convex_hull(mesh)
    closed = is_closed(np.asarray(mesh.faces))
    solid = mesh if closed else hull.mesh
    com = np.asarray(solid.center_mass if center_of_mass is None else center_of_mass, dtype=float)
    proj = hull.vertices @ hull.normals.T
    width = float(np.min(proj.max(axis=0) - proj.min(axis=0)))  # smallest width of the hull
    scale = max(size / float(np.ptp(hull.vertices, axis=0).max()), min_width / width)
    # Inertia per unit mass about the COM, scaled; mass itself does not change where a body rests.
    inertia = np.asarray(solid.moment_inertia, dtype=float) / max(float(solid.mass), 1e-300) * scale**2
    if solid is mesh and center_of_mass is not None:  # trimesh's inertia is about its own COM: shift it
        shift = (np.asarray(solid.center_mass) - com) * scale
        inertia += np.dot(shift, shift) * np.eye(3) - np.outer(shift, shift)
    normals = np.asarray(placement_normals, dtype=float).reshape(-1, 3)
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True) if len(normals) else normals
    extent = scale * float(np.ptp(hull.vertices, axis=0).max())  # of the simulated part, metres
    world = DropWorld(
        hull.vertices * scale,
        com * scale,
        inertia,
        friction=friction,
        rolling_friction=rolling_friction,
        time_step=time_step,
    )
    steps = dict(max_steps=int(max_seconds / time_step), window=int(1.0 / time_step), still_deg=0.1)

    def release(n: np.ndarray, tilt_deg: float) -> np.ndarray:
        """Down directions (part frame, ``(directions, 3)``) where the part settles, released resting on
        ``n`` tilted by ``tilt_deg`` about each of ``directions`` horizontal axes (seeded phase)."""
        R, _ = Rotation.align_vectors([_DOWN], [n])  # n to world down
        phi = rng.uniform(0.0, 2.0 * np.pi) + np.arange(directions) * 2.0 * np.pi / directions
        out = []
        for a in phi:
            tilt = Rotation.from_rotvec(np.radians(tilt_deg) * np.array([np.cos(a), np.sin(a), 0.0]))
            R_rest, _ = world.settle((tilt * R).as_matrix(), 1e-3 * extent, quasi_static=True, **steps)
            out.append(R_rest.T @ _DOWN)
        return np.array(out)

    try:
        settled: list[np.ndarray] = []
        unsettled = 0
        for R0 in Rotation.random(drops, random_state=int(rng.integers(2**31))).as_matrix():
            R, ok = world.settle(R0, drop_height * extent, **steps)
            unsettled += not ok
            if ok:
                settled.append(R.T @ _DOWN)
        stays = np.zeros(len(normals), dtype=bool)
        err = np.zeros(len(normals))
        rolled = np.zeros(len(normals), dtype=bool)
        for i, n in enumerate(normals):
            ends = release(n, hold_deg)  # (directions, 3)
            err[i] = float(_angle_deg(ends, n).max())
            stays[i] = err[i] < match_deg
            # Came to rest at the same COM height (within 5 %) elsewhere: a part on a curved side rolled
            # along it (a neutral rest), which toppling (the COM falls) is not.
            h0 = float((hull.vertices @ n).max() - n @ com)
            h = (hull.vertices @ ends.T).max(axis=0) - ends @ com
            rolled[i] = not stays[i] and bool(np.all(np.abs(h - h0) <= 0.05 * h0))

        rest_n = np.array(settled).reshape(-1, 3)
        labels = _cluster(rest_n, match_deg)
        k = int(labels.max()) + 1 if len(labels) else 0
        rests = np.zeros((k, 3))
        counts = np.bincount(labels, minlength=k)
        np.add.at(rests, labels, rest_n)
        rests /= np.maximum(np.linalg.norm(rests, axis=1, keepdims=True), 1e-12)
        match = np.full(k, -1, dtype=np.int64)
        if k and len(normals):
            ang = _angle_deg(rests, normals)
            best = ang.argmin(axis=1)
            match = np.where(ang[np.arange(k), best] < match_deg, best, -1)
        refused = np.asarray(refused_normals if refused_normals is not None else np.zeros((0, 3)), float)
        refused = refused.reshape(-1, 3)
        if k and len(refused):
            near = _angle_deg(rests, refused / np.linalg.norm(refused, axis=1, keepdims=True)).min(axis=1) < match_deg
            match = np.where((match < 0) & near, -2, match)
        # Rests on no reported placement are released too, tilted just past the margin's angle: a rest the
        # rule refuses should let the part go in some direction.
        rest_stays = np.ones(k, dtype=bool)
        for r in np.flatnonzero(match < 0):
            rest_stays[r] = bool(np.all(_angle_deg(release(rests[r], leave_deg), rests[r])[:, 0] < match_deg))
    finally:
        world.close()
    order = np.argsort(-counts, kind="stable")
    return DropReport(
        placement_normals=normals,
        rests=rests[order],
        rest_counts=counts[order],
        rest_match=match[order],
        rest_stays=rest_stays[order],
        stays=stays,
        rolled=rolled,
        release_error_deg=err,
        unsettled=unsettled,
        drops=drops,
    )
