"""The ``antipodal`` grasp planner: force-closure, collision-free parallel-jaw grasps.

Pipeline (part frame, metres, radians):

1. contact samples: area-weighted surface points plus planar facet centres;
2. the opposite contact by ray casting through the part along ``-normal``;
3. jaw opening within the stroke (with approach clearance) and the antipodal
   friction-cone test (``mu``, default 0.3: a 16.7 deg cone);
4. palm orientations sampled about the grasp axis;
5. pads on the surface: a grid of pad points is ray-cast onto the part along
   the jaw axis; a point is *supported* when the surface lies within
   ``pad_tolerance`` of the pad plane. No point may meet material in front of
   the plane (a protrusion), and at least ``pad_min_support`` of each pad must
   be supported; the rest may overhang an edge or a hole (1.0: pads fully on
   the surface);
6. quality score from the grasp axis' distance to the centre of mass, the
   normals' alignment with the axis and the pads' contact area;
7. in score order: near-duplicates dropped, then hand (palm, fingers and
   their approach sweep) against part collision with python-fcl.

Results are cached on disk per part mesh hash, centre of mass, settings, hand
and seed (``~/.cache/asmteach/grasps`` or ``$ASMTEACH_CACHE_DIR``).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import Field, ValidationError

from asmteach.core.errors import UserError
from asmteach.core.interfaces import GraspPlanner, PartModel
from asmteach.core.io import write_json
from asmteach.core.models import Grasp, HandSpec, StrictModel
from asmteach.core.parts import mesh_hash
from asmteach.plugins.planners.grasps.antipodal import antipodal_angles, friction_half_angle
from asmteach.plugins.planners.grasps.checks import check_graspable_width, check_mesh, check_wall_thickness
from asmteach.plugins.planners.grasps.hand_geometry import MeshCollider, hand_boxes, pad_grid
from asmteach.plugins.planners.grasps.sampling import ContactPairs, Raycaster, find_opposite_contacts, sample_surface

__all__ = ["AntipodalGraspPlanner", "AntipodalSettings", "default_cache_dir"]

log = logging.getLogger(__name__)

CACHE_VERSION = 1
# Fingers checked this far off the contact planes when closed (metres), so touching is not colliding.
_CONTACT_GAP = 2e-4


class ScoreWeights(StrictModel):
    """Weights of the quality terms (each term is in [0, 1]; the score is their weighted sum)."""

    com: float = Field(0.5, ge=0.0, description="grasp axis close to the centre of mass (less torque to resist)")
    alignment: float = Field(0.2, ge=0.0, description="contact normals along the grasp axis (deep in the cone)")
    pad: float = Field(0.3, ge=0.0, description="fraction of the pads' area in contact with the surface")


class AntipodalSettings(StrictModel):
    """Settings of :class:`AntipodalGraspPlanner` (metres, radians unless named ``*_deg``)."""

    mu: float = Field(0.3, gt=0.0, le=2.0, description="Coulomb friction coefficient of the friction-cone test")
    samples: int = Field(600, ge=10, le=100_000, description="area-weighted surface samples")
    facet_centres: bool = Field(True, description="also sample the centre of every planar facet")
    orientations: int = Field(24, ge=1, le=360, description="palm orientations sampled about each grasp axis")
    clearance: float = Field(0.002, ge=0.0, description="free space per side between fingers and part on approach")
    approach_sweep: float = Field(0.03, ge=0.0, description="hand boxes extended backward by this approach path")
    pad_grid: tuple[int, int] = Field((4, 5), description="pad sample points along the pad's x and z")
    pad_tolerance: float = Field(0.001, gt=0.0, description="surface within this distance of the pad plane")
    pad_inset: float = Field(0.0005, ge=0.0, description="pad samples kept this far inside the pad edge")
    pad_min_support: float = Field(
        0.5, gt=0.0, le=1.0, description="fraction of each pad that must lie on the surface (1.0: fully on it)"
    )
    min_thickness: float = Field(0.002, gt=0.0, description="walls thinner than this mark a thin shell")
    dedup_distance: float = Field(0.005, ge=0.0, description="TCPs closer than this ...")
    dedup_angle_deg: float = Field(15.0, ge=0.0, le=180.0, description="... and rotations closer than this are one")
    max_grasps: int = Field(300, ge=1, description="keep at most this many (best first)")
    weights: ScoreWeights = Field(default_factory=ScoreWeights)
    cache: bool = Field(True, description="read and write the on-disk cache")
    cache_dir: str | None = Field(None, description="cache folder; default $ASMTEACH_CACHE_DIR or ~/.cache/asmteach")


def default_cache_dir() -> Path:
    """``$ASMTEACH_CACHE_DIR/grasps`` or ``~/.cache/asmteach/grasps``."""
    base = os.environ.get("ASMTEACH_CACHE_DIR") or Path.home() / ".cache" / "asmteach"
    return Path(base) / "grasps"


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
        check_wall_thickness(widths, part.name, s.min_thickness)
        max_opening = hand.max_width - 2.0 * s.clearance
        check_graspable_width(widths, part.name, hand, max_opening)
        stats: dict[str, Any] = {"samples": len(widths), "pairs": len(pairs)}

        pairs = pairs.subset((pairs.width >= max(hand.min_width, s.min_thickness)) & (pairs.width <= max_opening))
        stats["in_stroke"] = len(pairs)
        angles = antipodal_angles(pairs.p0, pairs.n0, pairs.p1, pairs.n1)
        cone = friction_half_angle(s.mu)
        fc = np.all(angles <= cone, axis=1)
        pairs, angles = pairs.subset(fc), angles[fc]
        stats["force_closure"] = len(pairs)
        if len(pairs) == 0:
            raise UserError(
                f"part {part.name!r}: no force-closure pair within the stroke (friction cone "
                f"{np.degrees(cone):.1f} deg for mu={s.mu}); the opposite faces are not parallel enough"
            )

        R, pair_idx = self._orientations(pairs, mesh.extents)
        support = self._pad_support(rc, hand, pairs, R, pair_idx)
        ok_pad = support >= s.pad_min_support - 1e-9
        R, pair_idx, support = R[ok_pad], pair_idx[ok_pad], support[ok_pad]
        stats["pads_supported"] = len(pair_idx)
        if len(pair_idx) == 0:
            raise UserError(
                f"part {part.name!r}: no grasp has {s.pad_min_support:.0%} of both "
                f"{hand.pad_size[0] * 1000:.0f} x {hand.pad_size[1] * 1000:.0f} mm pads on the surface "
                "(faces too small or curved for the pads)"
            )
        score = self._score(part, pairs, angles, pair_idx, support, cone, mesh.extents)
        grasps, n_dup, n_col = self._select(part, hand, pairs, R, pair_idx, score)
        stats.update(duplicates=n_dup, colliding=n_col, kept=len(grasps))
        if not grasps:
            raise UserError(
                f"part {part.name!r}: all {len(pair_idx)} grasps with supported pads make the hand collide "
                "with the part"
            )
        return grasps, stats

    def _orientations(self, pairs: ContactPairs, extents: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """TCP rotations ``(m, 3, 3)`` (columns x, y, z) about each grasp axis, and their pair index."""
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
        return R, np.repeat(np.arange(n), k)

    def _pad_support(
        self, rc: Raycaster, hand: HandSpec, pairs: ContactPairs, R: np.ndarray, pair_idx: np.ndarray
    ) -> np.ndarray:
        """Supported fraction of the worse pad, per candidate; ``-1`` where material protrudes into a pad.

        Each pad point is cast from ``probe`` metres outside the pad plane toward
        the part along the jaw axis: it is supported when it enters the surface
        within ``pad_tolerance`` of the plane; an earlier hit is material in
        front of the pad (the candidate is refused), a later hit or none is a
        gap under the pad (an edge overhang or a hole).
        """
        s = self.settings
        grid = pad_grid(hand, s.pad_grid[0], s.pad_grid[1], inset=s.pad_inset)
        x, y, z = R[:, :, 0], R[:, :, 1], R[:, :, 2]
        offsets = grid[None, :, 0:1] * x[:, None, :] + grid[None, :, 1:2] * z[:, None, :]  # (m, g, 3)
        probe = s.pad_tolerance + max(s.clearance, 0.002)
        fractions = []
        blocked = np.zeros(len(R), dtype=bool)
        for contact, sign in ((pairs.p0[pair_idx], 1.0), (pairs.p1[pair_idx], -1.0)):
            direction = sign * y  # finger 0 pushes along +y, finger 1 along -y
            pts = contact[:, None, :] + offsets
            origins = pts - probe * direction[:, None, :]
            dirs = np.broadcast_to(direction[:, None, :], pts.shape).reshape(-1, 3)
            t, normals, _ = rc.cast(origins.reshape(-1, 3), dirs)
            entering = np.einsum("ij,ij->i", normals, dirs) < 0.0
            ok = (entering & (np.abs(t - probe) <= s.pad_tolerance)).reshape(len(R), -1)
            # A ray that starts inside material (it leaves instead of entering) or enters
            # before the plane meets something the pad would push into.
            early = (np.isfinite(t) & ((~entering) | (t < probe - s.pad_tolerance))).reshape(len(R), -1)
            blocked |= early.any(axis=1)
            fractions.append(ok.mean(axis=1))
        return np.where(blocked, -1.0, np.minimum(*fractions))

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

    def _select(
        self,
        part: PartModel,
        hand: HandSpec,
        pairs: ContactPairs,
        R: np.ndarray,
        pair_idx: np.ndarray,
        score: np.ndarray,
    ) -> tuple[list[Grasp], int, int]:
        """Best first: skip near-duplicates of kept grasps, then hand-part collisions.

        Checking duplicates before collisions gives the same set as filtering
        collisions first (a candidate is only ever compared with kept,
        collision-free grasps) while calling fcl far less.
        """
        s = self.settings
        collider = MeshCollider({"part": (part.mesh, np.eye(4))})
        cos_tol = np.cos(np.radians(s.dedup_angle_deg))
        order = np.argsort(-score, kind="stable")
        kept: list[int] = []
        kept_t = np.zeros((0, 3))
        kept_R = np.zeros((0, 3, 3))
        n_dup = n_col = 0
        for i in order:
            j = pair_idx[i]
            tcp = 0.5 * (pairs.p0[j] + pairs.p1[j])
            Ri = R[i]
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
                        continue
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = Ri, tcp
            width = float(pairs.width[j])
            # Closed on the part (fingers just off the contact planes) and open on the way in.
            closed = hand_boxes(hand, width + 2.0 * _CONTACT_GAP)
            approach = hand_boxes(hand, min(width + 2.0 * s.clearance, hand.max_width), sweep=s.approach_sweep)
            if collider.collides(closed, T) or collider.collides(approach, T):
                n_col += 1
                continue
            kept.append(int(i))
            kept_t = np.vstack([kept_t, tcp])
            kept_R = np.concatenate([kept_R, Ri[None]])
            if len(kept) >= s.max_grasps:
                break
        grasps = [
            Grasp(
                id=k,
                p0=pairs.p0[pair_idx[i]],
                p1=pairs.p1[pair_idx[i]],
                R=R[i],
                width=float(pairs.width[pair_idx[i]]),
                score=float(score[i]),
            )
            for k, i in enumerate(kept)
        ]
        return grasps, n_dup, n_col
