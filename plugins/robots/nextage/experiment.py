"""Reachability: IK success and precision over a grid of grasp poses on the table, per arm.

For every cell of an ``x, y`` grid on the table in front of the robot the
trial asks IK for a grasp pose with the TCP ``height`` above the table top:

* ``top``: approach straight down (TCP z = world -z), the jaw turned by each yaw;
* ``side``: approach horizontal, away from the robot (TCP z = world +x turned
  by each yaw about world z), the jaw horizontal.

A cell's score is the fraction of yaws with an IK solution (both finger orders
allowed) that is also collision-free against the table. Precision is the FK
residual of every solution (mm, deg). ``summarize`` writes a CSV of all cells and
a heat-map PNG per (arm, grasp) grid point.
"""

from __future__ import annotations

import csv
import io
import math
import time
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field

from asmteach.core import geometry, registry
from asmteach.core.config import check_plugin_settings
from asmteach.core.io import atomic_path, write_text
from asmteach.core.models import StrictModel
from asmteach.core.sweep import Experiment

__all__ = ["Reachability", "ReachabilityParams", "grasp_pose"]


class ReachabilityParams(StrictModel):
    """One reachability map (metres, degrees)."""

    robot: str = Field("nextage_pybullet", description="robot plugin name (asmteach.robots)")
    robot_settings: dict[str, Any] = Field(default_factory=dict)
    arm: str = "left"
    grasp: Literal["top", "side"] = "top"
    x_range: tuple[float, float] = Field((0.15, 0.75), description="world x of the grid, metres")
    y_range: tuple[float, float] = Field((-0.6, 0.6), description="world y of the grid, metres")
    nx: int = Field(13, ge=1, le=200)
    ny: int = Field(25, ge=1, le=200)
    height: float = Field(0.03, description="TCP height above the table top, metres")
    yaws_deg: list[float] = Field(default_factory=lambda: [0.0, 45.0, 90.0, 135.0], min_length=1)


def grasp_pose(kind: str, x: float, y: float, z: float, yaw: float) -> np.ndarray:
    """``T_world_tcp`` of a top-down or side grasp at ``(x, y, z)`` (metres), yaw in radians."""
    c, s = math.cos(yaw), math.sin(yaw)
    T = np.eye(4)
    if kind == "top":
        z_ax = np.array([0.0, 0.0, -1.0])
        y_ax = np.array([-s, c, 0.0])
    else:  # side: horizontal approach, horizontal jaw
        z_ax = np.array([c, s, 0.0])
        y_ax = np.array([-s, c, 0.0])
    x_ax = np.cross(y_ax, z_ax)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x_ax, y_ax, z_ax, [x, y, z]
    return T


class Reachability(Experiment):
    """IK reachability map of one arm for one grasp kind."""

    Params = ReachabilityParams

    def check(self, params: ReachabilityParams) -> None:
        """The robot plugin and its settings, before any trial."""
        check_plugin_settings(
            "robots", params.robot, params.robot_settings, name_key="params.robot", settings_key="params.robot_settings"
        )

    def run_trial(self, params: ReachabilityParams, seed: int, workdir: Path) -> dict[str, Any]:
        robot = registry.create("robots", params.robot, params.robot_settings, seed=seed)
        try:
            return self._map(robot, params)
        finally:
            robot.close()

    def _map(self, robot: Any, params: ReachabilityParams) -> dict[str, Any]:
        table_z = float(getattr(robot.settings, "table_height", 0.0))
        xs = np.linspace(*params.x_range, params.nx)
        ys = np.linspace(*params.y_range, params.ny)
        cells: list[list[float]] = []
        times: list[float] = []
        pos_err: list[float] = []
        rot_err: list[float] = []
        solved = feasible = asked = 0
        for x in xs:
            for y in ys:
                n_ok = 0
                for yaw in params.yaws_deg:
                    T = grasp_pose(params.grasp, float(x), float(y), table_z + params.height, math.radians(yaw))
                    t0 = time.perf_counter()
                    res = robot.ik(params.arm, T)
                    times.append(time.perf_counter() - t0)
                    asked += 1
                    if not res.success:
                        continue
                    solved += 1
                    T_fk = robot.fk(params.arm, res.q)
                    target = T @ np.diag([-1.0, -1.0, 1.0, 1.0]) if res.flipped else T
                    pos_err.append(float(np.linalg.norm(T_fk[:3, 3] - target[:3, 3])))
                    rot_err.append(geometry.rotation_distance(T_fk, target))
                    if not bool(robot.in_collision(params.arm, res.q[None])[0]):
                        n_ok += 1
                        feasible += 1
                cells.append([float(x), float(y), n_ok / len(params.yaws_deg)])
        return {
            "ik_success_rate": solved / asked,
            "feasible_rate": feasible / asked,
            "reachable_cells": float(np.mean([c[2] > 0 for c in cells])),
            "median_ms": 1000.0 * float(np.median(times)),
            "max_pos_err_mm": 1000.0 * max(pos_err, default=0.0),
            "max_rot_err_deg": math.degrees(max(rot_err, default=0.0)),
            "cells": cells,
            "nx": params.nx,
            "ny": params.ny,
        }

    def summarize(self, rows: list[dict[str, Any]], out_dir: Path) -> list[Path]:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        out: list[Path] = []
        buf = io.StringIO()
        w = csv.writer(buf)
        w.writerow(["arm", "grasp", "seed", "x", "y", "feasible_fraction"])
        for r in rows:
            if not r.get("ok"):
                continue
            pt, m = r.get("point", {}), r["metrics"]
            arm, grasp = pt.get("arm", "?"), pt.get("grasp", "?")
            for x, y, f in m["cells"]:
                w.writerow([arm, grasp, r.get("seed"), f"{x:.4f}", f"{y:.4f}", f"{f:.3f}"])
            cells = np.asarray(m["cells"])
            grid = cells[:, 2].reshape(int(m["nx"]), int(m["ny"]))
            fig, ax = plt.subplots(figsize=(7, 4))
            im = ax.imshow(
                grid,
                origin="lower",
                cmap="viridis",
                vmin=0.0,
                vmax=1.0,
                aspect="auto",
                extent=[cells[:, 1].min(), cells[:, 1].max(), cells[:, 0].min(), cells[:, 0].max()],
            )
            ax.set_xlabel("world y (m)")
            ax.set_ylabel("world x (m)")
            ax.set_title(
                f"{arm} arm, {grasp} grasps: feasible yaw fraction "
                f"(IK {100 * m['ik_success_rate']:.0f}%, median {m['median_ms']:.2f} ms)"
            )
            fig.colorbar(im, ax=ax)
            path = out_dir / f"reachability_{arm}_{grasp}_seed{r.get('seed')}.png"
            with atomic_path(path) as tmp:
                fig.savefig(tmp, dpi=110, bbox_inches="tight", format="png")
            plt.close(fig)
            out.append(path)
        out.append(write_text(out_dir / "reachability_cells.csv", buf.getvalue()))
        return out
