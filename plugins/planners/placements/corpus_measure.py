"""The placements stage of the ``part_corpus`` experiment: reported placements against a PyBullet drop test.

Implements ``asmteach_measure_part`` for ``stage == "placements"``: the
planner's placements of the part (as loaded from the user's file) are compared
with where the part settles when dropped from seeded random orientations and
when released tilted in each placement (:func:`~.drop_test.drop_test`).
``agree``: no rest the planner missed and no placement the part leaves.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from asmteach.core.hooks import hookimpl
from asmteach.core.interfaces import PartModel
from asmteach.core.rests.placements import plan_placements
from asmteach.plugins.planners.placements.drop_test import down_normal, drop_test

__all__ = ["asmteach_measure_part"]


@hookimpl
def asmteach_measure_part(
    part: PartModel, stage: str, seed: int, workdir: Path, options: dict[str, Any]
) -> dict[str, Any] | None:
    """Placements vs drop test; ``None`` for other stages."""
    if stage != "placements":
        return None
    t0 = time.perf_counter()
    res = plan_placements(part.mesh, part.center_of_mass, name=part.name)
    t1 = time.perf_counter()
    normals = np.array([down_normal(p.T_table_part) for p in res.placements]).reshape(-1, 3)
    refused = np.array([r.normal for r in res.rejected]).reshape(-1, 3)
    rep = drop_test(
        part.mesh, normals, res.center_of_mass, refused_normals=refused, drops=int(options.get("drops", 30)), seed=seed
    )
    return {
        "reported": rep.reported,
        "drop_rests": rep.found,
        "matched": rep.matched,
        "missed": rep.missed,
        "below_margin": rep.below_margin,
        "spurious": rep.spurious,
        "rolled": rep.rolled_away,
        "unsettled": rep.unsettled,
        "agree": rep.agrees,
        "plan_seconds": t1 - t0,
        "drop_seconds": time.perf_counter() - t1,
    }
