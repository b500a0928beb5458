"""Which grasp candidates the antipodal planner keeps: buckets by approach and resting pose, then round robin.

A shallow candidate whose approach is within 60 deg of straight down in
some resting pose belongs to the pose where it is steepest, and these
buckets are taken by the hand's clearance above the table in that pose
(highest first, in 2 mm steps), then by score; every other candidate belongs
to the nearest of ``approach_bins`` approach directions (centred and shallow
apart), best score first. Each round gives every bucket one kept grasp:
near-duplicates of kept grasps are skipped, then hand-part collisions
(python-fcl), until ``max_grasps`` are kept.

Turning a part over takes a grasp that approaches from above in two resting
poses: it picks the part up in one and puts it down in the other. A grasp
steep in one pose is nearly horizontal in a pose 90 deg away, so such grasps
approach along a *bridge* (:func:`bridge_directions`): the bisector of two
resting directions at most 120 deg apart, within 60 deg of straight down in
both. A shallow candidate steepest along a bridge belongs to that bridge's
bucket, taken by the hand's clearance above the table in the worse of its
two poses. Without them a peg standing on its head has only grasps on its
shank from above, horizontal once it lies down, and cannot be turned over.

Part frame, metres; TCP frames as :class:`~asmteach.core.models.Grasp` has them.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from asmteach.core.errors import UserError
from asmteach.core.hand_geometry import MeshCollider, hand_boxes
from asmteach.core.interfaces import PartModel
from asmteach.core.models import Grasp, HandSpec
from asmteach.core.rests.placements import compute_placements
from asmteach.plugins.planners.grasps.sampling import ContactPairs
from asmteach.plugins.planners.grasps.settings import AntipodalSettings

__all__ = [
    "CONTACT_GAP",
    "MIN_STEEPNESS",
    "Candidates",
    "bridge_directions",
    "resting_directions",
    "round_robin_queues",
    "select_grasps",
    "sphere_directions",
    "table_gaps",
]

# Fingers checked this far off the contact planes when closed (metres), so touching is not colliding.
CONTACT_GAP = 2e-4
# Shallow grasps are ranked by the hand's clearance above the table in steps of this (metres): finer
# differences are within the approach clearance (2 mm a side) and not worth a worse score.
_GAP_STEP = 0.002
# Approaches steeper than this (cosine to a resting pose's downward direction) are offered per resting pose.
MIN_STEEPNESS = 0.5


@dataclass
class Candidates:
    """Grasp candidates that pass the contact model (part frame): rotations, contact pair, set-back, contact."""

    R: np.ndarray
    """``(m, 3, 3)`` TCP rotations."""
    pair_idx: np.ndarray
    """``(m,)`` index into the contact pairs."""
    depth: np.ndarray
    """``(m,)`` set-back of the TCP along its -z from the contacts' midpoint (metres)."""
    support: np.ndarray
    """``(m,)`` the worse pad's torsion radius over a fully pressed pad's, in [0, 1]."""
    share: np.ndarray
    """``(m,)`` share of the worse pad in contact (a patch: up to 1; a line or a point: a few pad points)."""
    radius: np.ndarray
    """``(m,)`` the worse pad's torsion radius (metres)."""

    @property
    def shallow(self) -> np.ndarray:
        """``(m,)`` bool: at the shallowest set-back (else the pads are centred on the contacts)."""
        return self.depth > 0.0


def select_grasps(
    part: PartModel,
    hand: HandSpec,
    pairs: ContactPairs,
    cand: Candidates,
    score: np.ndarray,
    down: np.ndarray,
    s: AntipodalSettings,
    bridges: np.ndarray | None = None,
) -> tuple[list[Grasp], int, int, np.ndarray]:
    """Round robin over the buckets, best first in each: skip near-duplicates of kept grasps, then collisions.

    Each round gives every bucket that still has candidates one kept grasp
    (:func:`round_robin_queues`), until ``max_grasps`` are kept. Checking
    duplicates before collisions gives the same set as filtering collisions
    first (a candidate is only ever compared with kept, collision-free
    grasps) while calling fcl far less. The result is sorted by score, best
    first, ids ``0..n-1``; ``down``: resting directions (part frame); ``bridges``: ``(k, 2)`` pairs of their
    indices whose bisectors get buckets of their own (:func:`bridge_directions`). Also returns the duplicate
    and collision counts and the kept candidates' indices, in the grasps' order.
    """
    collider = MeshCollider({"part": (part.mesh, np.eye(4))})
    cos_tol = np.cos(np.radians(s.dedup_angle_deg))
    R = cand.R
    mid = 0.5 * (pairs.p0 + pairs.p1)[cand.pair_idx]
    tcp_all = mid - cand.depth[:, None] * R[:, :, 2]
    # The open hand on its way in: its fingers are what may hit the part (or the table) on the approach.
    opening = np.minimum(pairs.width[cand.pair_idx] + 2.0 * s.clearance, hand.max_width)
    if s.approach_opening == "full":
        opening = np.full(len(R), float(hand.max_width))
    queues = round_robin_queues(part, hand, cand, tcp_all, opening, down, score, s.approach_bins, bridges)
    kept: list[int] = []
    kept_t = np.zeros((0, 3))
    kept_R = np.zeros((0, 3, 3))
    n_dup = n_col = 0

    def accept(i: int) -> bool:
        nonlocal n_dup, n_col
        tcp, Ri = tcp_all[i], R[i]
        if len(kept):
            near = np.linalg.norm(kept_t - tcp, axis=1) < s.dedup_distance
            if np.any(near):
                # cos of the rotation angle from the trace, for R and for the
                # finger-swapped R (x, y negated): the same physical grasp.
                d = np.einsum("kij,ij->kj", kept_R[near], Ri)  # column-wise dot products
                same = (d.sum(1) - 1.0) / 2.0
                swap = (-d[:, 0] - d[:, 1] + d[:, 2] - 1.0) / 2.0
                if np.any(np.maximum(same, swap) > cos_tol + 1e-9):  # strictly closer than the angle
                    n_dup += 1
                    return False
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = Ri, tcp
        width = float(pairs.width[cand.pair_idx[i]])
        # Closed on the part and open on the way in. Closed, the fingers stand off the contact planes by
        # the pads' compliance: material within it is the pads' contact patch (the contact model's).
        closed = hand_boxes(hand, width + 2.0 * (CONTACT_GAP + s.compliance))
        approach = hand_boxes(hand, float(opening[i]), sweep=s.approach_sweep)
        if collider.collides(closed, T) or collider.collides(approach, T):
            n_col += 1
            return False
        return True

    while queues and len(kept) < s.max_grasps:
        for q in queues:
            while q:
                i = q.popleft()
                if accept(i):
                    kept.append(i)
                    kept_t = np.vstack([kept_t, tcp_all[i]])
                    kept_R = np.concatenate([kept_R, R[i][None]])
                    break
            if len(kept) >= s.max_grasps:
                break
        queues = [q for q in queues if q]
    kept.sort(key=lambda i: (-score[i], i))
    grasps = []
    for k, i in enumerate(kept):
        j = cand.pair_idx[i]
        off = cand.depth[i] * R[i][:, 2]
        grasps.append(
            Grasp(
                id=k,
                p0=pairs.p0[j] - off,
                p1=pairs.p1[j] - off,
                R=R[i],
                width=float(pairs.width[j]),
                score=float(score[i]),
            )
        )
    return grasps, n_dup, n_col, np.asarray(kept, dtype=int)


def resting_directions(part: PartModel) -> np.ndarray:
    """``(u, 3)`` unit vectors into the table (part frame) of the part's stable placements, most probable first.

    The placements are those the regrasp planner rests the part in (``compute_placements``); empty when
    they cannot be computed.
    """
    try:
        placements = compute_placements(part)
    except UserError:
        return np.zeros((0, 3))
    return np.array([p.T_table_part[:3, :3].T @ np.array([0.0, 0.0, -1.0]) for p in placements]).reshape(-1, 3)


def bridge_directions(down: np.ndarray, max_angle_deg: float = 120.0) -> tuple[np.ndarray, np.ndarray]:
    """Bisectors ``(k, 3)`` (part frame, unit) of the pairs of resting directions ``down`` (``(u, 3)``) at most
    ``max_angle_deg`` apart, and the pairs ``(k, 2)`` (indices into ``down``).

    A grasp approaching along a bisector comes from above in both poses (cosine ``cos(angle / 2)`` to each
    resting direction: at least 0.5 at 120 deg), so it can put the part down in one and have picked it up in
    the other. Bisectors within 5 deg of one already listed are left out (a symmetric part's poses give the
    same turn many times over), keeping the first pair, most probable poses first.
    """
    down = np.asarray(down, float).reshape(-1, 3)
    dirs: list[np.ndarray] = []
    pairs: list[tuple[int, int]] = []
    cos_max, cos_same = np.cos(np.radians(max_angle_deg)), np.cos(np.radians(5.0))
    for i in range(len(down)):
        for j in range(i + 1, len(down)):
            if float(down[i] @ down[j]) < cos_max - 1e-9:
                continue
            b = down[i] + down[j]
            n = float(np.linalg.norm(b))
            if n < 1e-9:
                continue
            b = b / n
            if any(float(b @ d) > cos_same for d in dirs):
                continue
            dirs.append(b)
            pairs.append((i, j))
    return np.array(dirs).reshape(-1, 3), np.array(pairs, dtype=int).reshape(-1, 2)


def table_gaps(
    part: PartModel, hand: HandSpec, R: np.ndarray, tcp: np.ndarray, opening: np.ndarray, down: np.ndarray
) -> np.ndarray:
    """``(m, u)`` clearance (metres) of the hand above the table with the part in each resting pose.

    ``R``, ``tcp``: ``(m, 3, 3)``, ``(m, 3)`` TCP poses in the part frame; ``opening``: ``(m,)`` jaw
    openings (metres); ``down``: ``(u, 3)`` resting directions (:func:`resting_directions`). The clearance
    is the table's height above the hand's lowest point (palm and finger boxes, by the boxes' support
    functions), both along the resting direction; negative when the hand would enter the table.
    """
    m = len(R)
    if len(down) == 0 or m == 0:
        return np.zeros((m, len(down)))
    hull = np.asarray(part.mesh.convex_hull.vertices, dtype=float)
    table = np.max(hull @ down.T, axis=0)  # (u,) how far the part reaches along each resting direction
    axes_u = np.einsum("mik,ui->muk", R, down)  # (m, u, 3): each TCP axis along each resting direction
    low = np.full((m, len(down)), -np.inf)
    for name, sign in (("palm", 0.0), ("finger0", -1.0), ("finger1", 1.0)):
        box = next(b for b in hand_boxes(hand, 0.0) if b.name == name)
        centre = np.broadcast_to(box.center, (m, 3)).copy()
        centre[:, 1] += sign * 0.5 * opening  # the fingers' inner faces at +-opening / 2
        reach = np.einsum("mk,muk->mu", centre, axes_u) + np.abs(axes_u) @ (0.5 * box.size)
        low = np.maximum(low, reach)
    return table[None, :] - (tcp @ down.T + low)


def sphere_directions(n: int) -> np.ndarray:
    """``(n, 3)`` unit vectors spread evenly over the sphere (a Fibonacci lattice; deterministic)."""
    i = np.arange(n) + 0.5
    polar = np.arccos(1.0 - 2.0 * i / n)
    azimuth = np.pi * (1.0 + np.sqrt(5.0)) * i
    return np.stack([np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar), np.cos(polar)], axis=1)


def round_robin_queues(
    part: PartModel,
    hand: HandSpec,
    cand: Candidates,
    tcp: np.ndarray,
    opening: np.ndarray,
    down: np.ndarray,
    score: np.ndarray,
    bins: int,
    bridges: np.ndarray | None = None,
) -> list[deque[int]]:
    """Candidate indices per bucket, in the order they are tried; the buckets in the order of their first
    candidate's score (ties by index everywhere, so the order is deterministic).

    A shallow candidate belongs to the resting pose (``down``) in which its approach is steepest, if
    within 60 deg of straight down (``MIN_STEEPNESS``): shallow grasps are there to keep the fingers off
    the table, so these buckets are taken by the hand's clearance above the table in that pose
    (:func:`table_gaps`), highest first in ``_GAP_STEP`` steps, then by score. Every other candidate
    belongs to the nearest of ``bins`` approach directions (centred or shallow apart), best score first.
    ``bridges``: ``(k, 2)`` pairs of indices into ``down`` (:func:`bridge_directions`); a shallow candidate
    steepest along one's bisector belongs to that bridge, taken by the hand's clearance in the worse of the
    two poses.
    """
    m = len(score)
    approach = cand.R[:, :, 2]
    bucket = np.argmax(approach @ sphere_directions(bins).T, axis=1) * 2 + cand.shallow.astype(int)
    steps = np.zeros(m)
    if len(down):
        pairs = np.zeros((0, 2), dtype=int) if bridges is None else np.asarray(bridges, dtype=int).reshape(-1, 2)
        mid = down[pairs[:, 0]] + down[pairs[:, 1]]
        dirs = np.concatenate([down, mid / np.linalg.norm(mid, axis=1, keepdims=True)])
        # a bridge pose's two resting poses; a resting pose is its own pair
        both = np.concatenate([np.repeat(np.arange(len(down))[:, None], 2, axis=1), pairs])
        cosines = approach @ dirs.T
        pose = np.argmax(cosines, axis=1)
        rest = cand.shallow & (cosines[np.arange(m), pose] >= MIN_STEEPNESS)
        gaps = table_gaps(part, hand, cand.R[rest], tcp[rest], opening[rest], down)
        k = np.arange(rest.sum())
        gap = np.minimum(gaps[k, both[pose[rest], 0]], gaps[k, both[pose[rest], 1]])
        bucket[rest] = 2 * bins + pose[rest]
        steps[rest] = -np.floor(gap / _GAP_STEP)
    order = np.lexsort((np.arange(m), -score, steps, bucket))
    starts = np.flatnonzero(np.r_[True, bucket[order][1:] != bucket[order][:-1]])
    groups = np.split(order, starts[1:])
    groups.sort(key=lambda g: (-score[g[0]], int(g[0])))
    return [deque(int(i) for i in g) for g in groups]
