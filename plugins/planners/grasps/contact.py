"""Contact of a flat soft pad with any surface: patches, lines and points, and the load they bear.

Model (TCP and part frame, metres, newtons). Each pad is a flat rectangle
(``HandSpec.pad_size``) covered with a compliant layer ``compliance`` metres
deep. The jaw closes along its axis ``y``; a pad's *gap field* is, for points
``(x, z)`` of the pad, the distance along the closing direction from the pad
plane through the planned contact to the part's surface (found by ray casting;
negative: material in front of the plane). The pad first touches the part at
the smallest gap ``g_min`` and compresses up to ``compliance``:

* **contact patch**: the pad points whose surface lies within ``compliance``
  of the first touch, ``g <= g_min + compliance``. On a plane that is the whole
  overlap of pad and face (a patch contact); on a cylinder a strip along its
  axis ``sqrt(8 r c)`` wide (a line contact); on a sphere a disc of radius
  ``sqrt(2 r c)`` (a point contact, made finite by the soft pad);
* **protrusion**: the planned contact must be in the patch, so no point of the
  part may stand more than ``compliance`` in front of the pad plane
  (``g_min >= -compliance``); a ray that starts inside material counts as an
  infinite protrusion;
* **pressure**: a Winkler (bed-of-springs) foam, pressure proportional to the
  compression ``g_min + compliance - g``; its resultant is the grip force;
* **torsion** (soft finger): a pad resists twisting about the grasp axis up to
  ``mu * F * r`` where ``r`` is the pressure-weighted mean distance of the
  patch from the contact (on the axis). A uniformly pressed disc of radius
  ``a`` gives ``2 a / 3``; a paraboloid one (a sphere) ``8 a / 15``.

The load check is the soft-finger limit surface (an ellipsoid, Howe and
Cutkosky 1996) with gravity perpendicular to the grasp axis, the worst case:
the two pads share the weight ``m g`` as tangential force and its moment
``m g d`` about the axis (``d``: the centre of mass's distance from the axis),
``(s m g / (2 mu F))^2 + (s m g d / (mu F (r0 + r1)))^2 <= 1`` with a safety
factor ``s``.

Set-backs: the pad slides back along ``-z`` by ``d`` while the contact stays
put, at most until the contact is ``edge_margin`` from the fingertip edge of
the pad (a contact at the very edge slips off it). The pad points of every
set-back form one strip of rows (:func:`pad_strip`), and each set-back reads
its window of rows. Every palm orientation about one contact pair's axis
shares the two pad planes, so the gap field is cast once per pair and finger
over a square grid (:func:`gap_grids`) and read by nearest grid point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from asmteach.core.models import HandSpec
from asmteach.plugins.planners.grasps.sampling import Raycaster

__all__ = ["GRAVITY", "PadContacts", "PadStrip", "gap_grids", "load_ratio", "pad_contacts", "pad_strip"]

GRAVITY = 9.81
"""m/s^2."""


@dataclass(frozen=True)
class PadStrip:
    """Sample points of a pad and of its set-backs, relative to the contact (pad plane coordinates, metres).

    ``x``: ``(nx,)`` across the pad; ``z``: ``(rows,)`` along the approach, from the pad's top edge
    (``+hz``) down to the bottom edge of the deepest set-back; ``windows[j]``: the ``nz`` row indices
    the pad covers at set-back ``set_backs[j]`` (the pad centre at ``z = -set_backs[j]``).
    """

    x: np.ndarray
    z: np.ndarray
    windows: np.ndarray
    set_backs: np.ndarray

    @property
    def points(self) -> np.ndarray:
        """``(nx * rows, 2)`` all strip points ``(x, z)``, x-major."""
        gx, gz = np.meshgrid(self.x, self.z, indexing="ij")
        return np.stack([gx.ravel(), gz.ravel()], axis=1)


def pad_strip(
    hand: HandSpec,
    nx: int,
    nz: int,
    *,
    inset: float = 0.0,
    edge_margin: float = 0.0,
    set_backs: bool = True,
    sub: int = 2,
) -> PadStrip:
    """The pad grid (``nx`` by ``nz`` points, ``inset`` metres inside the pad's edge) and its set-backs.

    Set-backs go from 0 until the contact is ``edge_margin`` metres from the pad's fingertip edge, in
    steps of the grid's row spacing divided by ``sub``; ``set_backs=False`` keeps only the centred pad.
    """
    hx = max(0.5 * float(hand.pad_size[0]) - inset, 0.0)
    hz = max(0.5 * float(hand.pad_size[1]) - inset, 0.0)
    x = np.linspace(-hx, hx, nx) if nx > 1 else np.zeros(1)
    if nz < 2 or hz == 0.0:
        return PadStrip(x, np.zeros(1), np.zeros((1, 1), dtype=int), np.zeros(1))
    step = 2.0 * hz / ((nz - 1) * sub)
    d_max = max(0.5 * float(hand.pad_size[1]) - edge_margin, 0.0)
    levels = int(np.floor(d_max / step + 1e-9)) + 1 if set_backs else 1
    rows = (nz - 1) * sub + levels
    z = hz - step * np.arange(rows)
    windows = np.arange(levels)[:, None] + sub * np.arange(nz)[None, :]
    return PadStrip(x, z, windows, step * np.arange(levels))


@dataclass
class PadContacts:
    """Contact of both pads per candidate and set-back: ``(m, levels)`` arrays (metres)."""

    protrusion: np.ndarray
    """Material stands more than ``compliance`` in front of a pad plane (or a pad starts inside the part)."""
    share: np.ndarray
    """Share of the worse pad's sample points in its contact patch."""
    points: np.ndarray
    """Sample points in the worse pad's contact patch (0: only the contact itself)."""
    torsion_radius: np.ndarray
    """``(m, levels, 2)`` each pad's pressure-weighted mean distance of its patch from the contact."""


def _perpendicular(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the plane normal to each row of ``y`` ``(n, 3)``."""
    ref = np.eye(3)[np.argmin(np.abs(y), axis=1)]
    u = np.cross(y, ref)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, np.cross(y, u)


def gap_grids(
    rc: Raycaster,
    contact: np.ndarray,
    push: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    half: int,
    spacing: float,
    probe: float,
    chunk: int = 200,
) -> np.ndarray:
    """``(n, 2 half + 1, 2 half + 1)`` gaps (metres) over a square grid in each pad plane.

    The plane goes through ``contact`` normal to ``push`` (the finger's closing direction); grid point
    ``(i, j)`` is ``contact + (i - half) spacing u + (j - half) spacing v``. The gap is the distance along
    ``push`` from the plane to the surface: ``inf`` where nothing lies under that point, ``-inf`` where the
    ray (started ``probe`` outside the plane) began inside material.
    """
    k = np.arange(-half, half + 1) * spacing
    out = []
    for s in range(0, len(contact), chunk):
        c, p, uu, vv = contact[s : s + chunk], push[s : s + chunk], u[s : s + chunk], v[s : s + chunk]
        pts = (
            c[:, None, None, :]
            + k[None, :, None, None] * uu[:, None, None, :]
            + k[None, None, :, None] * vv[:, None, None, :]
        )  # (n, g, g, 3)
        origins = pts - probe * p[:, None, None, :]
        dirs = np.broadcast_to(p[:, None, None, :], pts.shape).reshape(-1, 3)
        t, normals, _ = rc.cast(origins.reshape(-1, 3), dirs)
        entering = np.einsum("ij,ij->i", normals, dirs) < 0.0
        gap = np.where(np.isfinite(t), t - probe, np.inf)
        # A first hit that leaves material: the ray started inside it (a protrusion), or it grazed a curved
        # part's silhouette through an edge (no contact there); the origin's occupancy tells which.
        odd = np.flatnonzero(np.isfinite(t) & ~entering)
        if len(odd):
            gap[odd] = np.where(rc.inside(origins.reshape(-1, 3)[odd]), -np.inf, np.inf)
        out.append(gap.reshape(len(c), len(k), len(k)).astype(np.float32))
    return np.concatenate(out) if out else np.zeros((0, len(k), len(k)), dtype=np.float32)


def pad_contacts(
    rc: Raycaster,
    strip: PadStrip,
    p0: np.ndarray,
    p1: np.ndarray,
    R: np.ndarray,
    pair_idx: np.ndarray,
    compliance: float,
    probe: float,
    spacing: float = 0.00125,
    chunk: int = 4000,
) -> PadContacts:
    """The contact model (module docstring) for ``m`` candidates at every set-back of ``strip``.

    ``p0``, ``p1``: ``(n, 3)`` planned contact pairs (part frame) of finger 0 (pushing along
    ``y = (p1 - p0) / |p1 - p0|``) and finger 1 (``-y``); ``R``: ``(m, 3, 3)`` TCP rotations of the
    candidates, each about its pair's axis (``R[:, :, 1] = y[pair_idx]``); ``probe``: rays start this far
    outside the pad plane (more than ``compliance``).

    Every orientation about one pair's axis shares the pad planes, so the gaps are cast once per pair and
    finger over a square grid ``spacing`` metres apart that covers the pad at any rotation and set-back
    (:func:`gap_grids`), and each candidate's pad points read their nearest grid point.
    """
    m = len(R)
    levels = len(strip.set_backs)
    if m == 0:
        z = np.zeros((0, levels))
        return PadContacts(z.astype(bool), z, z.astype(int), np.zeros((0, levels, 2)))
    y = p1 - p0
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    u, v = _perpendicular(y)
    pts = strip.points
    half = int(np.ceil(np.max(np.hypot(pts[:, 0], pts[:, 1])) / spacing)) + 1
    grids = [gap_grids(rc, p0, y, u, v, half, spacing, probe), gap_grids(rc, p1, -y, u, v, half, spacing, probe)]
    results = []
    for s in range(0, m, chunk):
        sl = slice(s, s + chunk)
        results.append(_evaluate(grids, strip, R[sl], pair_idx[sl], u, v, half, spacing, compliance))
    return PadContacts(*(np.concatenate([r[i] for r in results]) for i in range(4)))


def _evaluate(
    grids: list[np.ndarray],
    strip: PadStrip,
    R: np.ndarray,
    pair_idx: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    half: int,
    spacing: float,
    compliance: float,
) -> tuple[np.ndarray, ...]:
    m = len(R)
    nx, rows = len(strip.x), len(strip.z)
    pts = strip.points
    x, z = R[:, :, 0], R[:, :, 2]
    uj, vj = u[pair_idx], v[pair_idx]
    # pad point (a, b) -> a x + b z in the pair's grid basis (u, v); finger 1 sees the same plane coordinates
    a, b = pts[None, :, 0], pts[None, :, 1]
    cu = a * np.einsum("ij,ij->i", x, uj)[:, None] + b * np.einsum("ij,ij->i", z, uj)[:, None]
    cv = a * np.einsum("ij,ij->i", x, vj)[:, None] + b * np.einsum("ij,ij->i", z, vj)[:, None]
    ii = np.clip(np.rint(cu / spacing).astype(np.int64) + half, 0, 2 * half)
    jj = np.clip(np.rint(cv / spacing).astype(np.int64) + half, 0, 2 * half)
    zw = strip.z[strip.windows]  # (levels, nz) pad-plane z of each window row, relative to the contact
    rho = np.hypot(strip.x[None, :, None], zw[:, None, :])  # (levels, nx, nz)
    levels = len(strip.set_backs)
    prot = np.zeros((m, levels), dtype=bool)
    shares, counts, radii = [], [], []
    for grid in grids:
        g = grid[pair_idx[:, None], ii, jj].reshape(m, nx, rows)
        win = np.moveaxis(g[:, :, strip.windows], 2, 1)  # (m, levels, nx, nz)
        # The planned contact itself is on the surface (gap 0) and under the pad at every set-back.
        g_min = np.minimum(win.min(axis=(2, 3)), 0.0)  # (m, levels)
        prot |= g_min < -compliance
        with np.errstate(invalid="ignore"):  # -inf - -inf where a pad starts inside material (refused anyway)
            depth = (g_min + compliance)[..., None, None] - win  # compression of each pad point
        inside = depth >= 0.0  # nan (refused candidates) is outside
        w = np.where(inside, depth, 0.0)
        w_c = g_min + compliance  # the contact's own compression
        with np.errstate(invalid="ignore", divide="ignore"):
            r = (w * rho[None]).sum(axis=(2, 3)) / (w.sum(axis=(2, 3)) + w_c)
        radii.append(np.where(np.isfinite(r), r, 0.0))
        n_in = inside.sum(axis=(2, 3))
        counts.append(n_in)
        shares.append(n_in / (nx * strip.windows.shape[1]))
    return prot, np.minimum(*shares), np.minimum(*counts), np.stack(radii, axis=-1)


def load_ratio(
    mass: float, force: float, mu: float, com_distance: np.ndarray, torsion_radii: np.ndarray, safety: float = 1.0
) -> np.ndarray:
    """Soft-finger limit-surface load (<= 1 holds) under gravity perpendicular to the grasp axis.

    ``mass`` kg, ``force`` N per pad, ``com_distance`` ``(...)`` metres from the axis, ``torsion_radii``
    ``(..., 2)`` metres (module docstring).
    """
    weight = safety * mass * GRAVITY
    tangential = weight / (2.0 * mu * force)
    r = torsion_radii.sum(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        torque = np.where(r > 0.0, weight * com_distance / (mu * force * r), np.where(com_distance > 0.0, np.inf, 0.0))
    return np.hypot(tangential, torque)
