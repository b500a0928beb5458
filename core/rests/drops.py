"""Rests drawn the way a dropped part lands: trimesh's quasi-static drop probabilities.

Random scenes (the run's start poses, the part corpus' detection scenes) draw a
rest by how likely a dropped part lands on it. :func:`drop_rests` is the one
call of ``trimesh.poses.compute_stable_poses`` in the project; its rests are the
placements of :mod:`.placements` (123 of 125 over the 20 parts of sets 1 and 2,
equal to 2.5e-16; the other two fail the ``d / h`` margin) with the same landing
probabilities to 3 digits. The seeded scenes keep trimesh's own order of rests,
which breaks ties between equally likely rests by float round-off: drawing from
:func:`~.placements.resting_poses` instead would replay another scene for 379 of
600 seeded start scenes (10 structures x seeds 0-59), so every seeded run and
regression test would need its seed found again.

Frames: ``T`` maps part-frame points (metres) to a frame resting on the plane z = 0.
"""

from __future__ import annotations

import numpy as np
import trimesh

__all__ = ["drop_rests", "likely_rests"]


def drop_rests(mesh: trimesh.Trimesh, com: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(T (k, 4, 4), probability (k,))`` of every rest trimesh finds for ``mesh`` with its centre of mass ``com``."""
    T, p = trimesh.poses.compute_stable_poses(mesh, center_mass=np.asarray(com, dtype=float))
    return np.asarray(T, dtype=float), np.asarray(p, dtype=float)


def likely_rests(
    T: np.ndarray, p: np.ndarray, *, min_probability: float = 0.0, min_share: float = 0.0, likeliest_first: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """The rests at least ``min_probability`` likely and ``min_share`` of the likeliest, probabilities summing to 1.

    The likeliest rest is always kept. ``likeliest_first`` sorts them by
    probability (ties in trimesh's order of equal keys under numpy's default sort).
    """
    top = float(p.max())
    keep = (p >= min(min_probability, top)) & (p >= min_share * top)
    T, p = T[keep], p[keep]
    if likeliest_first:
        order = np.argsort(-p)
        T, p = T[order], p[order]
    return T, p / p.sum()
