"""The one entry point, :func:`decompose`: the first route that applies to a part, cached on disk and in memory."""

from __future__ import annotations

import hashlib
import json
import logging
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from asmteach.core.convex_pieces.measure import fidelity
from asmteach.core.convex_pieces.meshes import coacd_pieces, split_convex
from asmteach.core.convex_pieces.pieces import ConvexDecomposition, DecompositionSettings, hull_corners
from asmteach.core.convex_pieces.refine import refine_protruding
from asmteach.core.convex_pieces.solids import solid_pieces
from asmteach.core.interfaces import PartModel
from asmteach.core.io import atomic_path, cache_root

log = logging.getLogger(__name__)

CACHE_VERSION = 4
"""Bump when a change to the code changes the pieces it makes (old cache files are then ignored)."""


# ----------------------------------------------------------------------------- settings and result


def default_cache_dir() -> Path:
    """``convex_pieces`` in :func:`asmteach.core.io.cache_root` (``$ASMTEACH_CACHE_DIR``, ``$XDG_CACHE_HOME``)."""
    return cache_root() / "convex_pieces"


def cache_key(part: PartModel, settings: DecompositionSettings) -> str:
    """Hash of everything the decomposition depends on: mesh, solid spec (if any), settings, code version."""
    from asmteach.core.parts import mesh_hash

    solid = part.spec.solid.model_dump(mode="json") if part.spec.solid is not None else None
    blob = json.dumps(
        {
            "v": CACHE_VERSION,
            "mesh": part.source_hash or mesh_hash(part.mesh),
            "solid": solid,
            "settings": asdict(settings),
        },
        sort_keys=True,
    )
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


def _cache_path(part: PartModel, key: str, cache_dir: Path | None) -> Path:
    safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in part.name)[:40]
    return (cache_dir or default_cache_dir()) / f"{safe}-{key}.npz"


def _save(path: Path, key: str, d: ConvexDecomposition) -> None:
    counts = np.array([len(v) for v in d.pieces], dtype=np.int64)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(
            fh,
            key=np.array(key),
            method=np.array(d.method),
            counts=counts,
            vertices=np.vstack(d.pieces).astype("<f8"),
            figures=np.array([d.hausdorff, d.protrusion, d.volume_error, d.uncovered, d.seconds]),
        )


def _load(path: Path, key: str) -> ConvexDecomposition | None:
    """The cached decomposition, or ``None`` when the file is missing, damaged or of another key."""
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["key"]) != key:
                raise ValueError("the file holds another part's or settings' pieces")
            counts, verts, figures = z["counts"], z["vertices"], z["figures"]
            method = str(z["method"])
        if counts.sum() != len(verts) or verts.ndim != 2 or verts.shape[1] != 3 or (counts < 4).any():
            raise ValueError("piece counts do not match the vertices")
        if not np.all(np.isfinite(verts)) or len(figures) != 5:
            raise ValueError("non-finite vertices or missing figures")
        pieces = np.split(verts, np.cumsum(counts)[:-1])
        h, p, v, u, s = (float(x) for x in figures)
        return ConvexDecomposition(pieces, method, h, p, v, u, s, cached=True)
    except Exception as exc:  # noqa: BLE001 - zip, npy and key errors alike: a damaged cache is rebuilt, not fatal
        log.warning("convex pieces cache %s is unreadable (%s); rebuilding it", path, exc)
        return None


_MEMO: dict[str, ConvexDecomposition] = {}
"""Decompositions already made or read in this process (plan re-checks spawn the same parts many times)."""


def decompose(
    part: PartModel, settings: DecompositionSettings | None = None, *, cache: bool = True, cache_dir: Path | None = None
) -> ConvexDecomposition:
    """Convex pieces of ``part`` (part frame, metres) by the first route that applies (see
    :mod:`asmteach.core.convex_pieces`).

    ``cache``: read and write the on-disk cache (``cache_dir``, default
    :func:`default_cache_dir`); a failed write only costs a rebuild next time.
    """
    s = settings or DecompositionSettings()
    key = cache_key(part, s)
    if cache and key in _MEMO:
        return _MEMO[key]
    path = _cache_path(part, key, cache_dir)
    result = _load(path, key) if cache else None
    if result is None:
        result = _build(part, s)
        if cache:
            try:
                _save(path, key, result)
            except OSError as exc:
                log.warning("cannot cache convex pieces at %s: %s", path, exc)
    if cache:
        _MEMO[key] = result
    return result


def _build(part: PartModel, s: DecompositionSettings) -> ConvexDecomposition:
    t0 = time.perf_counter()
    mesh = part.mesh

    def done(
        pieces: list[np.ndarray], method: str, figures: tuple[float, float, float, float] | None = None
    ) -> ConvexDecomposition:
        h, p, v, u = figures or fidelity(pieces, mesh, s.samples, s.seed)
        return ConvexDecomposition(pieces, method, h, p, v, u, time.perf_counter() - t0)

    if part.spec.solid is not None:
        return done(solid_pieces(part.spec.solid, s.min_thickness), "solid")
    hull = mesh.convex_hull
    if float(hull.volume) - float(mesh.volume) <= 1e-6 * float(hull.volume):
        # nearly convex by volume; a long part can still hide a shallow dent the hull would fill: measure
        hull_v = [np.asarray(hull.vertices, dtype=float)]
        hull_fig = fidelity(hull_v, mesh, s.samples, s.seed)
        if hull_fig[1] <= s.tolerance:
            return done(hull_v, "convex", hull_fig)
    split, approx = split_convex(mesh, s.max_pieces)
    split_v = [v for v in (hull_corners(np.asarray(p.vertices)) for p in split) if v is not None]
    split_fig = fidelity(split_v, mesh, s.samples, s.seed)
    # judged by what collides: protrusion and uncovered surface (:func:`~asmteach.core.convex_pieces.measure.fidelity`)
    if max(split_fig[1], split_fig[3]) <= s.tolerance:
        return done(split_v, "plane_split", split_fig)
    co = coacd_pieces(mesh, s)
    if co:
        # CoACD's pieces bridge concavities within its normalised threshold: cut those that protrude again
        co = refine_protruding(co, mesh, s.tolerance, max(s.refine_max_pieces, 2 * len(co)), s.seed)
    co_fig = fidelity(co, mesh, s.samples, s.seed) if co else (np.inf, np.inf, np.inf, np.inf)
    log.info(
        "%s: plane split left %d hulls (protrusion %.3g mm), CoACD protrusion %.3g mm",
        part.name,
        approx,
        1e3 * split_fig[1],
        1e3 * co_fig[1],
    )
    if max(split_fig[1], split_fig[3]) <= max(co_fig[1], co_fig[3]):
        return done(split_v, "plane_split", split_fig)
    return done(co, "coacd", co_fig)
