"""Experiment ``grasp_hold``: plan grasps of each library part and lift-and-shake a sample of them.

One trial is one part (grid key ``part``, a part name of the library). It
plans grasps with the ``antipodal`` planner without the cache (timed), counts
the distinct collision-free force-closure grasps, picks ``grasps_per_part`` of
them at random (from the trial seed) and runs the PyBullet hold check on each.
Metrics: ``hold_rate``, ``held``, ``tested``, ``distinct_grasps``,
``plan_seconds``, drift statistics and the convex decomposition's volume error.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import Field

from asmteach.core.config import check_plugin_settings
from asmteach.core.convex_pieces import pieces_volume_error
from asmteach.core.errors import UserError
from asmteach.core.interfaces import PartModel
from asmteach.core.io import atomic_path, write_text
from asmteach.core.models import StrictModel
from asmteach.core.parts import build_part, load_structure
from asmteach.core.sweep import Experiment, to_markdown
from asmteach.plugins.planners.grasps.commands import load_hand
from asmteach.plugins.planners.grasps.hold_check import HoldSimulator
from asmteach.plugins.planners.grasps.planner import AntipodalGraspPlanner

__all__ = ["GraspHold", "GraspHoldParams", "library_parts"]


class GraspHoldParams(StrictModel):
    """Parameters of one ``grasp_hold`` trial."""

    library: list[str] = Field(
        default_factory=lambda: ["../parts/set1", "../parts/set2"],
        description="folders of structure YAMLs, relative to the experiment file",
    )
    part: str = Field(description="name of the part to test (part_a or part_b of a structure in the library)")
    hand: str = Field("nextage", description="a robot whose gripper (nextage, urdf_arm) or a HandSpec YAML/JSON file")
    planner: dict[str, Any] = Field(default_factory=dict, description="antipodal planner settings")
    grasps_per_part: int = Field(20, ge=1, description="grasps drawn at random from the planned ones")
    friction: float = Field(0.3, gt=0.0, description="pad-part friction coefficient in the simulator")
    lift: float = Field(0.10, gt=0.0, description="metres")
    hold_seconds: float = Field(2.0, ge=0.0)
    shake_amplitude: float = Field(0.01, ge=0.0, description="metres")
    shake_hz: float = Field(2.0, ge=0.0)


def library_parts(folders: list[Path]) -> dict[str, PartModel]:
    """Every part (A and B) of every structure YAML in ``folders``, by part name."""
    parts: dict[str, PartModel] = {}
    for folder in folders:
        if not folder.is_dir():
            raise UserError(f"library folder {folder} does not exist")
        for path in sorted(folder.glob("*.yaml")):
            task = load_structure(path)
            for spec in (task.part_a, task.part_b):
                parts.setdefault(spec.name, build_part(spec, path.parent))
    return parts


class GraspHold(Experiment):
    """Hold rate, distinct grasp count and planning time per library part."""

    Params = GraspHoldParams

    def check(self, params: GraspHoldParams) -> None:
        """The planner's settings by the antipodal planner's model, before any trial."""
        check_plugin_settings(
            "grasp_planners", "antipodal", params.planner, name_key="params", settings_key="params.planner"
        )

    def run_trial(self, params: GraspHoldParams, seed: int, workdir: Path) -> dict[str, Any]:
        folders = [self.path(f) for f in params.library]
        parts = library_parts(folders)
        if params.part not in parts:
            raise UserError(f"part {params.part!r} is not in the library ({', '.join(sorted(parts))})")
        part = parts[params.part]
        # a file named relative to the experiment file, else a robot whose gripper it is
        hand_spec = str(self.path(params.hand)) if self.path(params.hand).is_file() else params.hand
        hand = load_hand(hand_spec)
        planner = AntipodalGraspPlanner({**params.planner, "cache": False}, seed=seed)
        t0 = time.perf_counter()
        grasps = planner.plan(part, hand)
        plan_seconds = time.perf_counter() - t0
        rng = np.random.default_rng([seed, 7])
        chosen = rng.choice(len(grasps), size=min(params.grasps_per_part, len(grasps)), replace=False)
        results = []
        with HoldSimulator(hand, part, friction=params.friction) as sim:
            for i in chosen:
                results.append(
                    sim.check(
                        grasps[int(i)],
                        lift=params.lift,
                        hold=params.hold_seconds,
                        shake_amplitude=params.shake_amplitude,
                        shake_hz=params.shake_hz,
                    )
                )
            volume_error = pieces_volume_error(part, sim.pieces)
            n_pieces = len(sim.pieces)
        held = sum(r.held for r in results)
        drift = np.array([r.drift for r in results])
        lines = [f"{int(i)},{grasps[int(i)].score:.4f},{r.held},{r.drift:.6f},{r.drift_angle:.6f},{r.reason}"
                 for i, r in zip(chosen, results, strict=True)]  # fmt: skip
        write_text(workdir / "holds.csv", "grasp,score,held,drift_m,drift_rad,reason\n" + "\n".join(lines) + "\n")
        return {
            "part": part.name,
            "hold_rate": held / len(results),
            "held": held,
            "tested": len(results),
            "distinct_grasps": len(grasps),
            "plan_seconds": round(plan_seconds, 4),
            "drift_median_mm": round(float(np.median(drift)) * 1000, 3),
            "drift_max_mm": round(float(np.max(drift)) * 1000, 3),
            "convex_pieces": n_pieces,
            "convex_volume_error": round(volume_error, 4),
            **{
                f"stage_{k}": v for k, v in planner.last_stats.items() if isinstance(v, int) and not isinstance(v, bool)
            },
        }

    def summarize(self, rows: list[dict[str, Any]], out_dir: Path) -> list[Path]:
        ok = [r["metrics"] for r in rows if r.get("ok")]
        if not ok:
            return []
        ok.sort(key=lambda m: m["part"])
        held = sum(m["held"] for m in ok)
        tested = sum(m["tested"] for m in ok)
        table = [
            {
                "part": m["part"],
                "hold_rate": m["hold_rate"],
                "held/tested": f"{m['held']}/{m['tested']}",
                "distinct_grasps": m["distinct_grasps"],
                "plan_s": m["plan_seconds"],
                "drift_max_mm": m["drift_max_mm"],
                "convex_vol_err": m["convex_volume_error"],
            }
            for m in ok
        ]
        md = (
            f"# grasp_hold\n\nOverall hold rate {held}/{tested} = {held / max(tested, 1):.3f}; "
            f"fewest distinct grasps {min(m['distinct_grasps'] for m in ok)}; "
            f"slowest planning {max(m['plan_seconds'] for m in ok):.3f} s.\n\n" + to_markdown(table)
        )
        paths = [write_text(out_dir / "grasp_hold.md", md)]
        paths.append(self._plot(ok, out_dir / "grasp_hold.png"))
        return paths

    @staticmethod
    def _plot(ok: list[dict[str, Any]], path: Path) -> Path:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        names = [m["part"] for m in ok]
        fig = Figure(figsize=(max(6.0, 0.5 * len(names) + 2), 6.0), dpi=100)
        FigureCanvasAgg(fig)
        ax1, ax2 = fig.subplots(2, 1, sharex=True)
        x = np.arange(len(names))
        ax1.bar(x, [m["hold_rate"] for m in ok], color="#2ca02c")
        ax1.axhline(0.95, color="k", ls="--", lw=1, label="target 95 %")
        ax1.set_ylim(0, 1.05)
        ax1.set_ylabel("hold rate")
        ax1.legend(loc="lower right", fontsize=8)
        ax2.bar(x, [m["distinct_grasps"] for m in ok], color="#1f77b4")
        ax2.axhline(40, color="k", ls="--", lw=1, label="target 40")
        ax2.set_ylabel("distinct grasps")
        ax2.legend(loc="lower right", fontsize=8)
        ax2.set_xticks(x, names, rotation=60, ha="right", fontsize=8)
        fig.tight_layout()
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png")
        return path
