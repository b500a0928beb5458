"""The ``antipodal`` grasp planner: force-closure, collision-free parallel-jaw grasps.

Pipeline (part frame, metres, radians):

1. contact samples: area-weighted surface points plus planar facet centres;
2. the opposite contact by ray casting through the part along ``-normal``:
   the first exit (across a wall) and, when the ray enters the part again
   (a tube's bore, a wheel's window), the last exit too (across the part);
3. jaw opening within the stroke (with approach clearance) and the antipodal
   friction-cone test (``mu``, default 0.3: a 16.7 deg cone); none left: the
   part has no opposing surfaces;
4. palm orientations about the grasp axis: ``orientations`` evenly spaced,
   plus, per stable resting pose of the part (the placements the regrasp
   planner uses), the one approaching most steeply from above in that pose,
   and per pair of the ``bridge_poses`` most probable poses at most 120 deg
   apart, the one nearest their bisector (a grasp from above in both, that
   can turn the part over from one to the other);
5. the soft-pad contact model (:mod:`.contact`): each pad is flat with a
   ``compliance`` deep soft layer; the surface within that depth of the first
   touch is its contact patch (a patch on a plane, a strip on a cylinder, a
   disc on a sphere), no point of the part may stand more than ``compliance``
   in front of the pad plane through the planned contact (a protrusion), and
   the two patches must bear ``hold_safety`` times the part's weight and its
   moment about the grasp axis (soft-finger limit surface: friction ``mu``,
   ``hand.max_force`` per pad, each patch's torsion radius). Optionally
   ``pad_min_support`` of each pad must be in contact (1.0: pads fully on a
   face); by default line and point contacts on curved parts are accepted;
6. set-backs: besides the pads centred on the contacts, every orientation is
   also offered with the TCP moved back along its approach axis (-z) as far
   as the contact model still holds, at most until the contacts are
   ``edge_margin`` from the pads' fingertip edge. Such a *shallow* grasp holds
   the part near the fingertip end of the pads, and the fingertips reach that much less past
   the contacts: a side grasp from above with centred pads puts the fingertips
   (half a pad length past the TCP) into the table whenever the contacts are
   lower than that, which is most side faces of a part lying on the table;
7. quality score from the grasp axis' distance to the centre of mass, the
   normals' alignment with the axis and the contact patches' torsion radius;
8. selection, round robin over buckets, one kept grasp per bucket and round
   until ``max_grasps`` are kept: near-duplicates dropped, then hand (palm,
   fingers and their approach sweep, the hand fully open on its way in as the
   robot opens it) against part collision with python-fcl.
   A shallow candidate whose approach is within 60 deg of straight down in
   some resting pose belongs to the pose where it is steepest, and these
   buckets are taken by the hand's clearance above the table in that pose
   (highest first, in 2 mm steps), then by score; every other candidate
   belongs to the nearest of ``approach_bins`` approach directions (centred
   and shallow apart), best score first. One grasp set serves every pose of
   the part, and each pose can only use the grasps that approach from above
   it; the best scores overall would fill the set with a dozen contact pairs
   near the centre of mass, in all their orientations.

A shallow grasp's ``p0``, ``p1`` are the pad centres on the two contact planes
(the TCP is their midpoint, as :class:`~asmteach.core.models.Grasp` has it);
they may lie past the part's edge by up to half a pad length, and the sampled
contacts lie under the pads.

When no grasp is left, :class:`UserError` says why in one line: too small,
a thin shell, too wide (its smallest width against the stroke), no opposing
surfaces, no surface the pads can press, too heavy, or the hand collides.

Results are cached on disk per part mesh hash, centre of mass, settings, hand
and seed (``~/.cache/asmteach/grasps`` or ``$ASMTEACH_CACHE_DIR``).
"""

from __future__ import annotations

import hashlib
import json
import logging
import time
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

from asmteach.core.errors import UserError
from asmteach.core.interfaces import GraspPlanner, PartModel
from asmteach.core.io import cache_root, write_json
from asmteach.core.models import Grasp, HandSpec
from asmteach.core.parts import mesh_hash
from asmteach.plugins.planners.grasps.antipodal import antipodal_angles, friction_half_angle
from asmteach.plugins.planners.grasps.checks import (
    check_graspable_width,
    check_mesh,
    check_too_small,
    check_wall_thickness,
)
from asmteach.plugins.planners.grasps.contact import PadStrip, load_ratio, pad_contacts, pad_strip
from asmteach.plugins.planners.grasps.sampling import ContactPairs, Raycaster, find_opposite_contacts, sample_surface
from asmteach.plugins.planners.grasps.selection import (
    MIN_STEEPNESS,
    Candidates,
    bridge_directions,
    resting_directions,
    select_grasps,
)
from asmteach.plugins.planners.grasps.settings import AntipodalSettings

__all__ = ["AntipodalGraspPlanner", "default_cache_dir"]

log = logging.getLogger(__name__)

CACHE_VERSION = 5
# Shallow grasps set back less than this (metres) are the centred grasp again, for every purpose.
_MIN_SET_BACK = 1e-3


def default_cache_dir() -> Path:
    """``grasps`` in :func:`asmteach.core.io.cache_root` (``$ASMTEACH_CACHE_DIR``, ``$XDG_CACHE_HOME``)."""
    return cache_root() / "grasps"


class AntipodalGraspPlanner(GraspPlanner):
    """Antipodal parallel-jaw grasps of a part in free space (see the module docstring).

    ``plan`` raises :class:`UserError` when the part cannot be grasped at all,
    naming the stage that removed the last candidate. ``last_stats`` holds the
    candidate counts per stage and the planning time of the last call.
    """

    Settings = AntipodalSettings
    settings: AntipodalSettings

    def __init__(self, settings: AntipodalSettings | dict[str, Any] | None = None, *, seed: int = 0) -> None:
        super().__init__(settings, seed=seed)
        self.last_stats: dict[str, Any] = {}

    # ------------------------------------------------------------------ cache
    def cache_key(self, part: PartModel, hand: HandSpec) -> str:
        """Hash of everything the result depends on."""
        s = self.settings.model_dump(mode="json", exclude={"cache", "cache_dir"})
        blob = json.dumps(
            {
                "v": CACHE_VERSION,
                "mesh": part.source_hash or mesh_hash(part.mesh),
                "com": np.round(np.asarray(part.center_of_mass, dtype=float), 7).tolist(),
                "settings": s,
                "hand": hand.model_dump(mode="json"),
                "seed": self.seed,
            },
            sort_keys=True,
        )
        return hashlib.sha256(blob.encode()).hexdigest()[:24]

    def _cache_path(self, part: PartModel, hand: HandSpec) -> Path:
        root = Path(self.settings.cache_dir) if self.settings.cache_dir else default_cache_dir()
        safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in part.name)
        return root / f"{safe}-{self.cache_key(part, hand)}.json"

    def _load_cache(self, path: Path) -> list[Grasp] | None:
        if not path.is_file():
            return None
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            return [Grasp.model_validate(g) for g in data["grasps"]]
        except (OSError, ValueError, KeyError, TypeError, ValidationError):
            log.warning("ignoring unreadable grasp cache %s", path)
            return None

    # ------------------------------------------------------------------ planning
    def plan(self, part: PartModel, hand: HandSpec) -> list[Grasp]:
        """Grasps of ``part`` for ``hand`` in the part frame, best first, ids ``0..n-1``."""
        cache_path = self._cache_path(part, hand) if self.settings.cache else None
        if cache_path is not None:
            cached = self._load_cache(cache_path)
            if cached is not None:
                self.last_stats = {"cache_hit": True, "kept": len(cached), "seconds": 0.0}
                return cached
        t0 = time.perf_counter()
        grasps, stats = self._plan(part, hand)
        stats["seconds"] = time.perf_counter() - t0
        stats["cache_hit"] = False
        self.last_stats = stats
        if cache_path is not None:
            try:
                write_json(
                    cache_path,
                    {"part": part.name, "stats": stats, "grasps": [g.model_dump(mode="json") for g in grasps]},
                )
            except OSError as exc:  # a read-only cache must not stop planning
                log.warning("cannot write grasp cache %s: %s", cache_path, exc)
        return grasps

    def _plan(self, part: PartModel, hand: HandSpec) -> tuple[list[Grasp], dict[str, Any]]:
        s = self.settings
        mesh = part.mesh
        check_mesh(mesh, part.name)
        rc = Raycaster(mesh)
        samples = sample_surface(mesh, s.samples, self.rng(1), facet_centres=s.facet_centres, raycaster=rc)
        pairs, widths = find_opposite_contacts(samples, rc)
        max_opening = hand.max_width - 2.0 * s.clearance
        # walls: the first exit of each sample's ray; graspable widths: every pair, across cavities too
        all_widths = np.concatenate([widths, pairs.width])
        check_too_small(all_widths, part.name, hand, s.min_thickness)
        check_wall_thickness(widths, part.name, s.min_thickness)
        check_graspable_width(all_widths, part.name, hand, max_opening, mesh=mesh)
        stats: dict[str, Any] = {"samples": len(widths), "pairs": len(pairs)}
        self.last_stats = stats  # filled in as planning goes, so a refusal leaves the counts that led to it

        pairs = pairs.subset((pairs.width >= max(hand.min_width, s.min_thickness)) & (pairs.width <= max_opening))
        stats["in_stroke"] = len(pairs)
        angles = antipodal_angles(pairs.p0, pairs.n0, pairs.p1, pairs.n1)
        cone = friction_half_angle(s.mu)
        fc = np.all(angles <= cone, axis=1)
        pairs, angles = pairs.subset(fc), angles[fc]
        stats["force_closure"] = len(pairs)
        if len(pairs) == 0:
            raise UserError(
                f"part {part.name!r}: no opposing surfaces: no two faces within the hand's "
                f"{max_opening * 1000:.1f} mm opening face each other within the friction cone "
                f"({np.degrees(cone):.1f} deg for mu={s.mu}), so a parallel jaw would squeeze it out; grasp it with a "
                "fixture or another gripper, or raise mu if the pads really grip better"
            )

        # A round part rests in hundreds of poses (a sphere on each facet), each nearly improbable: the
        # most probable ones get their own steepest approach (the rest are covered by the orientation grid).
        down = resting_directions(part)[: s.rest_poses]
        # Grasps that turn the part over: between two of the most probable poses (module docstring, step 4).
        bridge_dirs, bridges = bridge_directions(down[: s.bridge_poses])
        stats["bridges"] = len(bridges)
        R, pair_idx = self._orientations(pairs, mesh.extents, np.concatenate([down, bridge_dirs]))
        stats["candidates"] = len(pair_idx)
        cand, counts = self._contacts(part, rc, hand, pairs, R, pair_idx)
        stats.update(counts)
        stats["pads_supported"] = len(cand.pair_idx)  # passed the contact model (name kept for the benchmarks)
        stats["shallow"] = int(np.count_nonzero(cand.shallow))
        if len(cand.pair_idx) == 0:
            raise UserError(self._no_contact_reason(part, hand, counts))
        score = self._score(part, pairs, angles, cand.pair_idx, cand.support, cone, mesh.extents)
        grasps, n_dup, n_col, kept = select_grasps(part, hand, pairs, cand, score, down, s, bridges)
        stats.update(duplicates=n_dup, colliding=n_col, kept=len(grasps))
        if len(kept):
            stats["contact_share_median"] = round(float(np.median(cand.share[kept])), 3)
            stats["torsion_radius_median_mm"] = round(float(np.median(cand.radius[kept])) * 1000, 2)
        if not grasps:
            raise UserError(
                f"part {part.name!r}: all {len(cand.pair_idx)} grasps in contact make the hand collide with the "
                "part (no room for the fingers beside the contacts)"
            )
        return grasps, stats

    def _no_contact_reason(self, part: PartModel, hand: HandSpec, counts: dict[str, int]) -> str:
        """One line naming why no candidate passed the contact model (``counts`` from :meth:`_contacts`)."""
        s = self.settings
        c = s.compliance * 1000
        if counts["protruding"] == counts["candidates"]:
            return (
                f"part {part.name!r}: no opposing surfaces the pads can press: at every antipodal pair, material "
                f"stands more than the pads' {c:.1f} mm compliance in front of a pad (the contacts lie in pockets, "
                f"grooves or beside ridges narrower than the {hand.pad_size[0] * 1000:.0f} x "
                f"{hand.pad_size[1] * 1000:.0f} mm pads); use narrower fingers or softer pads (compliance)"
            )
        if counts["overloaded"] > 0 and counts["short_support"] == 0:
            return (
                f"part {part.name!r}: too heavy for the hand: {part.mass:.3g} kg; no grasp bears "
                f"{s.hold_safety:g}x its weight and moment about the grasp axis with {hand.max_force:g} N per pad "
                f"at mu={s.mu}; use a stronger gripper, or check the part's mass/density"
            )
        return (
            f"part {part.name!r}: no grasp has {s.pad_min_support:.0%} of both {hand.pad_size[0] * 1000:.0f} x "
            f"{hand.pad_size[1] * 1000:.0f} mm pads in contact (faces too small or curved); lower pad_min_support "
            "(0 accepts line and point contacts)"
        )

    def _orientations(
        self, pairs: ContactPairs, extents: np.ndarray, down: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """TCP rotations ``(m, 3, 3)`` (columns x, y, z) about each grasp axis, and their pair index.

        ``orientations`` evenly spaced ones per pair, then, per pair and resting
        direction ``down`` (``(u, 3)``, part frame, into the table), the one
        approaching most steeply from above with the part resting that way: ``z``
        is the resting direction projected onto the plane normal to the grasp
        axis (kept when that leaves at least ``MIN_STEEPNESS`` of it).
        """
        n, k = len(pairs), self.settings.orientations
        y = (pairs.p1 - pairs.p0) / pairs.width[:, None]
        # Reference direction: the part axis least aligned with the grasp axis, so that
        # axis-aligned approaches are among the sampled ones for boxy parts.
        ref = np.eye(3)[np.argmin(np.abs(y), axis=1)]
        x0 = np.cross(y, ref)
        x0 /= np.linalg.norm(x0, axis=1, keepdims=True)
        z0 = np.cross(x0, y)
        # Facet centres keep the regular angle grid; random samples get a random offset for variety.
        offset = np.where(pairs.from_facet, 0.0, self.rng(2).random(n) * 2.0 * np.pi / k)
        theta = offset[:, None] + 2.0 * np.pi * np.arange(k)[None, :] / k
        c, s_ = np.cos(theta)[..., None], np.sin(theta)[..., None]
        x = c * x0[:, None, :] + s_ * z0[:, None, :]
        yy = np.broadcast_to(y[:, None, :], x.shape)
        z = np.cross(x, yy)
        R = np.stack([x, yy, z], axis=-1).reshape(n * k, 3, 3)
        pair_idx = np.repeat(np.arange(n), k)
        if len(down) == 0:
            return R, pair_idx
        # The grid's random offsets tilt most approaches a few degrees off the vertical of every placement;
        # a tilted finger reaches lower on one side, and on a low part that is the difference.
        proj = down[None, :, :] - np.einsum("nj,uj->nu", y, down)[..., None] * y[:, None, :]  # (n, u, 3)
        norm = np.linalg.norm(proj, axis=2)
        pi, ui = np.nonzero(norm >= MIN_STEEPNESS)
        zr = proj[pi, ui] / norm[pi, ui, None]
        R_rest = np.stack([np.cross(y[pi], zr), y[pi], zr], axis=-1)
        return np.concatenate([R, R_rest]), np.concatenate([pair_idx, pi])

    def _contacts(
        self,
        part: PartModel,
        rc: Raycaster,
        hand: HandSpec,
        pairs: ContactPairs,
        R: np.ndarray,
        pair_idx: np.ndarray,
    ) -> tuple[Candidates, dict[str, int]]:
        """Candidates passing the contact model (:mod:`.contact`), centred and at their shallowest set-back.

        Per orientation and set-back ``d`` (the TCP and both pads moved by ``-d * z``, the contacts under
        the pads): refused when material stands more than ``compliance`` in front of a pad plane, when a
        pad's share in contact is under ``pad_min_support``, or when the two contact patches cannot bear
        ``hold_safety`` times the part's weight and moment about the grasp axis. Kept: the centred grasp
        when it passes, and the deepest passing set-back of at least ``_MIN_SET_BACK``. Returns the
        candidates and the refusal counts (``candidates``, ``protruding``, ``short_support``,
        ``overloaded``), each counted at the centred pad.
        """
        s = self.settings
        strip = pad_strip(
            hand, s.pad_grid[0], s.pad_grid[1], inset=s.pad_inset, edge_margin=s.edge_margin, set_backs=s.set_backs
        )
        probe = s.compliance + max(s.clearance, 0.002)
        pc = pad_contacts(rc, strip, pairs.p0, pairs.p1, R, pair_idx, s.compliance, probe)
        y = R[:, :, 1]
        rel = np.asarray(part.center_of_mass, dtype=float)[None, :] - pairs.p0[pair_idx]
        d_com = np.linalg.norm(rel - np.einsum("ij,ij->i", rel, y)[:, None] * y, axis=1)
        load = load_ratio(part.mass, hand.max_force, s.mu, d_com[:, None], pc.torsion_radius, s.hold_safety)
        if s.hold_safety == 0.0:
            load = np.zeros_like(load)
        short = pc.share < s.pad_min_support - 1e-9
        loaded = load > 1.0
        good = ~pc.protrusion & ~short & ~loaded  # (m, levels)
        counts = {
            "candidates": len(R),
            "protruding": int(np.count_nonzero(pc.protrusion[:, 0])),
            "short_support": int(np.count_nonzero(~pc.protrusion[:, 0] & short[:, 0])),
            "overloaded": int(np.count_nonzero(~pc.protrusion[:, 0] & ~short[:, 0] & loaded[:, 0])),
        }
        levels = len(strip.set_backs)
        deepest = levels - 1 - np.argmax(good[:, ::-1], axis=1)
        deep = good.any(axis=1) & (strip.set_backs[deepest] >= _MIN_SET_BACK)
        keep_c = np.flatnonzero(good[:, 0])
        keep_s = np.flatnonzero(deep)
        lv = np.concatenate([np.zeros(len(keep_c), dtype=int), deepest[keep_s]])
        idx = np.concatenate([keep_c, keep_s])
        radius = pc.torsion_radius[idx, lv].min(axis=1)
        full = _full_pad_radius(strip)
        return Candidates(
            R=R[idx],
            pair_idx=pair_idx[idx],
            depth=strip.set_backs[lv],
            support=np.minimum(radius / full, 1.0) if full > 0 else np.ones(len(idx)),
            share=pc.share[idx, lv],
            radius=radius,
        ), counts

    def _score(
        self,
        part: PartModel,
        pairs: ContactPairs,
        angles: np.ndarray,
        pair_idx: np.ndarray,
        margin: np.ndarray,
        cone: float,
        extents: np.ndarray,
    ) -> np.ndarray:
        """Weighted quality in [0, sum of weights]; higher is better."""
        w = self.settings.weights
        p0 = pairs.p0[pair_idx]
        axis = (pairs.p1 - pairs.p0)[pair_idx] / pairs.width[pair_idx, None]
        rel = np.asarray(part.center_of_mass, dtype=float)[None, :] - p0
        d_axis = np.linalg.norm(rel - np.einsum("ij,ij->i", rel, axis)[:, None] * axis, axis=1)
        s_com = 1.0 - np.minimum(d_axis / (0.5 * float(np.linalg.norm(extents))), 1.0)
        s_align = 1.0 - angles[pair_idx].max(axis=1) / cone if cone > 0 else np.ones(len(pair_idx))
        return w.com * s_com + w.alignment * s_align + w.pad * margin


def _full_pad_radius(strip: PadStrip) -> float:
    """Torsion radius (metres) of a pad fully and evenly pressed, about its centre: the mean distance of its
    sample points from the centre (the reference of the ``pad`` score)."""
    z = strip.z[strip.windows[0]]
    return float(np.mean(np.hypot(strip.x[:, None], z[None, :] - z.mean())))
