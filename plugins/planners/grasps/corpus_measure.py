"""The grasp planner's part in ``asmteach check-part`` and in the ``part_corpus`` experiment.

``asmteach_check_part``: how many grasps the ``antipodal`` planner finds for
the Nextage hand, or the reason it finds none (too wide for the stroke, too
small, no opposing surfaces, too heavy). ``asmteach_measure_part`` (stage
``grasps``): the same plan, then grasps hold-tested one by one in PyBullet
(:class:`~.hold_check.HoldSimulator`: close, lift, hold under a shake) in an
order spread over the kept list, until ``target`` held or ``max_trials`` ran.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from asmteach.core.errors import UserError
from asmteach.core.hooks import hookimpl
from asmteach.core.interfaces import PartModel
from asmteach.core.models import Grasp
from asmteach.plugins.planners.grasps.commands import load_hand
from asmteach.plugins.planners.grasps.hold_check import HoldSimulator
from asmteach.plugins.planners.grasps.planner import AntipodalGraspPlanner

__all__ = ["asmteach_check_part", "asmteach_measure_part", "spread_order"]


_DOES_NOT_FIT = ("too wide", "no graspable width", "too small", "too heavy")
"""Refusals that say the part does not fit the hand (its opening, its pads, its force): no target applies."""


def spread_order(n: int) -> list[int]:
    """``0..n-1`` in an order spread over the list: first, last, then midpoints at halving steps."""
    order: list[int] = []
    seen: set[int] = set()
    step = n
    while len(order) < n:
        for i in [*range(0, n, max(step, 1)), n - 1]:
            if i not in seen:
                seen.add(i)
                order.append(i)
        if step <= 1:
            break
        step //= 2
    return order


def _plan(part: PartModel, seed: int) -> tuple[list[Grasp], str, dict[str, Any]]:
    planner = AntipodalGraspPlanner({"cache": False}, seed=seed)
    try:
        grasps, reason = planner.plan(part, load_hand("nextage")), ""
    except UserError as exc:  # an ungraspable part is a result: its reason is the finding
        grasps, reason = [], str(exc)
    return grasps, reason, dict(planner.last_stats)


@hookimpl
def asmteach_check_part(part: PartModel, out_dir: Path | None) -> list[tuple[str, str, str]]:
    """Grasp count for the Nextage hand, or why there is none."""
    grasps, reason, _ = _plan(part, seed=0)
    if not grasps:
        return [("grasps", "fail", reason or "no grasp found")]
    return [
        (
            "grasps",
            "ok",
            f"{len(grasps)} parallel-jaw grasps for the Nextage hand (hold-tested in the part_corpus experiment)",
        )
    ]


@hookimpl
def asmteach_measure_part(
    part: PartModel, stage: str, seed: int, workdir: Path, options: dict[str, Any]
) -> dict[str, Any] | None:
    """Grasps planned and hold-tested; ``None`` for other stages."""
    if stage != "grasps":
        return None
    target, max_trials = int(options.get("target", 30)), int(options.get("max_trials", 45))
    t0 = time.perf_counter()
    grasps, reason, stats = _plan(part, seed)
    plan_s = time.perf_counter() - t0
    tried = held = 0
    if grasps:
        with HoldSimulator(load_hand("nextage"), part, friction=float(options.get("friction", 0.5))) as sim:
            for i in spread_order(len(grasps)):
                if held >= target or tried >= max_trials:
                    break
                tried += 1
                held += int(sim.check(grasps[i]).held)
    return {
        "fits_hand": bool(grasps) or not any(why in reason for why in _DOES_NOT_FIT),
        "candidates": int(stats.get("candidates", 0) or 0),
        "grasps": len(grasps),
        "tried": tried,
        "holding": held,
        "reason": reason,
        "plan_seconds": plan_s,
        "hold_seconds": time.perf_counter() - t0 - plan_s,
    }
