"""Random start scenes for simulated runs: parts in random stable placements on the table.

Stable resting poses come from trimesh's ``compute_stable_poses``; only
poses with probability of at least ``min_probability`` are drawn, weighted by
it. Each part gets a uniform yaw and a position in its own region of the
table, so the two parts never overlap: A on one side (+y or -y, chosen by the
seed), B on the other.

The rests and their probabilities come from :func:`asmteach.core.rests.drops.drop_rests`
(trimesh's drop probabilities; its docstring says why the seeded scenes keep them).

Frames: ``T_world_part`` 4x4, metres; the table top at ``table_height``.
"""

from __future__ import annotations

import numpy as np
import trimesh

from asmteach.core.config import SceneSettings
from asmteach.core.geometry import compose, from_rotation, rot_z
from asmteach.core.interfaces import PartModel
from asmteach.core.rests.drops import drop_rests, likely_rests

__all__ = ["random_start_poses", "stable_poses"]


def stable_poses(part: PartModel, min_probability: float) -> tuple[np.ndarray, np.ndarray]:
    """``(transforms (k, 4, 4), probabilities (k,))``: resting poses on z = 0, most likely first."""
    T, p = drop_rests(part.mesh, part.center_of_mass)
    return likely_rests(T, p, min_probability=min_probability, likeliest_first=True)


def random_start_poses(
    parts: list[PartModel], table_height: float, settings: SceneSettings, rng: np.random.Generator
) -> list[np.ndarray]:
    """One ``T_world_part`` per part: a random stable pose, yaw and position, the parts on opposite sides."""
    side = 1.0 if rng.random() < 0.5 else -1.0
    out = []
    for k, part in enumerate(parts):
        Ts, probs = stable_poses(part, settings.min_probability)
        T_rest = Ts[int(rng.choice(len(Ts), p=probs))]
        # centre the resting part's footprint on the chosen xy
        verts = trimesh.transform_points(part.mesh.vertices, T_rest)
        centre = 0.5 * (verts.min(axis=0) + verts.max(axis=0))
        T_rest = compose(from_rotation(np.eye(3), [-centre[0], -centre[1], -verts[:, 2].min()]), T_rest)
        x = rng.uniform(*settings.x_range)
        y = side * (1.0 if k % 2 == 0 else -1.0) * rng.uniform(*settings.y_range)
        yaw = rng.uniform(-np.pi, np.pi)
        out.append(compose(from_rotation(np.eye(3), [x, y, table_height]), rot_z(yaw), T_rest))
    return out
