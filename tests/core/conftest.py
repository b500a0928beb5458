"""A real third-party plugin distribution, made in a temporary folder.

It is a ``*.dist-info`` with ``entry_points.txt`` and a module, put on
``sys.path``; importlib.metadata discovers it exactly as it would an
installed wheel. Nothing in asmteach is monkeypatched.
"""

from __future__ import annotations

import importlib
import sys
import textwrap
from pathlib import Path

import pytest

PLUGIN_MODULE = '''
from pathlib import Path
import numpy as np
from pydantic import Field
from asmteach.core import interfaces as I
from asmteach.core.models import StrictModel, Correction, Detection
from asmteach.core.sweep import Experiment


class DetSettings(StrictModel):
    voxel_size: float = Field(0.002, gt=0.0, description="metres")
    mode: str = "fast"


class ToyDetector(I.Detector):
    Settings = DetSettings

    def detect(self, cloud, part, table=None, viewpoint=None):
        return Detection(part=part.name, found=False, reason="toy")


class ToyTeacher(I.Teacher):
    def teach(self, frames, camera, task):
        return task


class ToyCorrector(I.Corrector):
    def correct(self, T_world_part, part, table, cloud=None, viewpoint=None):
        return Correction(T_world_part=T_world_part)


class ToyGrasps(I.GraspPlanner):
    def plan(self, part, hand):
        return []


class ToyMotion(I.MotionPlanner):
    def plan(self, start, goal, *, lower, upper, is_valid, cost=None, time_limit=5.0):
        return I.MotionResult(success=True, path=np.vstack([start, goal]))


class ToyRobot(I.Robot):
    arms = ["left"]
    hand = None

    def joint_names(self, arm): return ["j0"]
    def joint_limits(self, arm): return np.array([-1.0]), np.array([1.0])
    def home(self, arm): return np.zeros(1)
    def fk(self, arm, q): return np.eye(4)
    def ik(self, arm, T, q_seed=None): return I.IKResult(success=False, q=None, reason="toy")
    def set_obstacles(self, obstacles): pass
    def attach(self, arm, part, T_tcp_part=None, *, width=None): pass
    def in_collision(self, arm, qs, *, ignore=()): return np.zeros(len(qs), bool)
    def clearance(self, arm, qs, upto=np.inf): return np.ones(len(qs))


class ToyAssembly(I.AssemblyPlanner):
    def plan(self, problem, robot, motion_planner, *, progress=None):
        from asmteach.core.models import Plan
        return I.AssemblyResult(success=False, plan=Plan(), reason="toy")


class SquareParams(StrictModel):
    x: float = 1.0
    fail_above: float = 1e9


class Square(Experiment):
    """Toy experiment: metric = x^2 + seed; fails when x > fail_above."""
    Params = SquareParams

    def run_trial(self, params, seed, workdir):
        if params.x > params.fail_above:
            raise ValueError(f"x={params.x} too large")
        (workdir / "done.txt").write_text("ok")
        return {"square": params.x ** 2 + seed, "x": params.x}

    def summarize(self, rows, out_dir):
        p = Path(out_dir) / "square.txt"
        p.write_text(str(len(rows)))
        return [p]
'''

BROKEN_MODULE = "raise ImportError('toy plugin is broken on purpose')\n"

ENTRY_POINTS = """
[asmteach.detectors]
toy_detector = toy_asmteach_plugin:ToyDetector
broken_detector = toy_asmteach_broken:Thing

[asmteach.teachers]
toy_teacher = toy_asmteach_plugin:ToyTeacher

[asmteach.correctors]
toy_corrector = toy_asmteach_plugin:ToyCorrector

[asmteach.grasp_planners]
toy_grasps = toy_asmteach_plugin:ToyGrasps

[asmteach.motion_planners]
toy_motion = toy_asmteach_plugin:ToyMotion

[asmteach.robots]
toy_robot = toy_asmteach_plugin:ToyRobot

[asmteach.assembly_planners]
toy_assembly = toy_asmteach_plugin:ToyAssembly

[asmteach.experiments]
toy_square = toy_asmteach_plugin:Square
"""


@pytest.fixture
def toy_dist(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Install the toy plugin distribution on sys.path; returns its site folder."""
    site = tmp_path / "site"
    info = site / "toy_asmteach_plugin-1.2.3.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: toy-asmteach-plugin\nVersion: 1.2.3\n")
    (info / "entry_points.txt").write_text(textwrap.dedent(ENTRY_POINTS))
    (site / "toy_asmteach_plugin.py").write_text(PLUGIN_MODULE)
    (site / "toy_asmteach_broken.py").write_text(BROKEN_MODULE)
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("PYTHONPATH", str(site))
    importlib.invalidate_caches()
    yield site
    for name in ("toy_asmteach_plugin", "toy_asmteach_broken"):
        sys.modules.pop(name, None)


@pytest.fixture
def toy_square_experiment(tmp_path: Path, toy_dist: Path) -> Path:
    """An experiment file of the toy ``toy_square`` kind: x in {1, 2, 3} x 2 seeds, trials fail above 2.5."""
    path = tmp_path / "square.yaml"
    path.write_text("experiment: toy_square\nparams: {fail_above: 2.5}\ngrid:\n  x: [1.0, 2.0, 3.0]\nseeds: 2\n")
    return path


@pytest.fixture
def toy_config(tmp_path: Path, toy_dist: Path) -> Path:
    """A valid run config naming only the toy plugins; returns its path."""
    repo = Path(__file__).resolve().parents[2]
    cfg = tmp_path / "run.yaml"
    cfg.write_text(
        textwrap.dedent(
            f"""
            name: toy
            seed: 3
            structure: {repo / "configs/parts/set1/stacked_blocks.yaml"}
            teacher: {{plugin: toy_teacher}}
            detector: {{plugin: toy_detector, settings: {{voxel_size: 0.004}}}}
            corrector: {{plugin: toy_corrector}}
            grasp_planner: {{plugin: toy_grasps}}
            motion_planner: {{plugin: toy_motion}}
            robot: {{plugin: toy_robot}}
            """
        )
    )
    return cfg
