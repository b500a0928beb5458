"""The run config's sections as strict models: :class:`RunConfig` and its ``table``, ``execution`` and plugin choices.

Paths in a run config are relative to the config's folder; lengths in
metres, angles in degrees where the key says so (``*_deg``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, field_validator

from asmteach.core.models import StrictModel, resolve_relative

__all__ = [
    "MAX_SEED",
    "ROLE_OF_KEY",
    "ExecutionSettings",
    "PluginChoice",
    "RunConfig",
    "SceneSettings",
    "TableSettings",
]


class PluginChoice(StrictModel):
    """Which plugin fills a role, and its settings (validated by the plugin)."""

    plugin: str = Field(description="entry-point name within the role's group (`asmteach plugins` lists them)")
    settings: dict[str, Any] = Field(
        default_factory=dict, description="the plugin's own settings, validated by its Settings model"
    )


Coordinate = Annotated[float, Field(ge=-5.0, le=5.0)]
"""A world coordinate within 5 m of the origin (metres); NaN fails the bounds."""
Extent = Annotated[float, Field(gt=0.0, le=5.0)]
"""A positive length up to 5 m (metres); NaN fails the bounds."""


class TableSettings(StrictModel):
    """The work table in front of the robot (world frame, metres).

    One place owns each number: ``height`` is the run's (the simulated table,
    the planners' table plane and the detectors' all use it); ``center`` and
    ``size`` are the robot plugin's own table (its ``table_center`` /
    ``table_size`` settings) unless written here, in which case the run loader
    (:mod:`asmteach.core.run_setup`) hands them to the robot and checks that
    the parts' start region lies on that table. The rendered detection scenes
    of the ``cvfh`` plugin use their own scene table when they are ``None``.
    """

    height: float = Field(0.0, ge=-2.0, le=2.0, description="table top z in the world frame, metres")
    center: tuple[Coordinate, Coordinate] | None = Field(
        None, description="table centre x, y in the world frame, metres; null: the robot plugin's own table"
    )
    size: tuple[Extent, Extent] | None = Field(
        None, description="table extent along world x, y, metres; null: the robot plugin's own table"
    )


class SceneSettings(StrictModel):
    """Where the parts start: world x and |world y| ranges of each part's footprint centre (metres).

    A on one side of the robot (+y or -y, chosen by the seed), B on the other
    (:func:`asmteach.core.scene.random_start_poses`).
    """

    x_range: tuple[float, float] = Field((0.30, 0.44), description="world x of a part's centre, [low, high] metres")
    y_range: tuple[float, float] = Field(
        (0.14, 0.28), description="|world y| of a part's centre, [low, high] metres (both sides)"
    )
    min_probability: float = Field(
        0.05, ge=0.0, le=1.0, description="least likely resting pose drawn (probability 0..1)"
    )


class ExecutionSettings(StrictModel):
    """The run config's ``execution`` section: the simulated world and what is recorded."""

    scene: SceneSettings = Field(
        default_factory=SceneSettings, description="where the parts start on the table (world x, |y|, metres)"
    )
    animation: bool = Field(True, description="record an animated GIF of the execution (execution.gif)")
    animation_fps: float = Field(4.0, gt=0.0, le=30.0, description="GIF frames per simulated second, 1/s")
    success_position_mm: float = Field(
        2.0, gt=0.0, description="success needs B's position in A's frame within this of T_A_B, millimetres"
    )
    success_angle_deg: float = Field(
        2.0, gt=0.0, description="success needs B's rotation in A's frame within this of T_A_B, degrees"
    )
    success_a_goal_mm: float = Field(
        3.0, gt=0.0, description="success needs A within this of its planned goal position, millimetres"
    )
    depth_frames: int = Field(
        4,
        ge=1,
        le=30,
        description="depth frames stacked into the cloud each time the parts are looked at: the noise is new in "
        "every frame, and four frames cut the peg's detection error from 0.3-0.7 mm to 0.1-0.4 mm (demo seeds 0, 1, "
        "19, 49, 57, 63), against the hole's 0.5 mm clearance",
    )
    recheck_plan: bool = Field(True, description="re-check the plan with the robot's independent collision check")
    look_again: Literal["never", "ambiguous", "always"] = Field(
        "always",
        description="when to detect A again once it stands at its goal: 'ambiguous' only when its first detection "
        "was (a twin pose explained the view as well); the assembly is planned again if A is not at its goal, and "
        "B's insertion is aimed at the A that is seen if it is a little off (reaim_mm, reaim_deg)",
    )
    reaim_mm: float = Field(
        0.8,
        ge=0.0,
        description="A seen at its goal puts B's assembled pose this far (millimetres) from the planned one: B's "
        "insertion is planned again into the A that is seen. The detection there is 0.1-0.5 mm off (A itself is put "
        "down 0.1 mm off as a rule); below this, aiming at what is seen adds more error than it removes",
    )
    reaim_deg: float = Field(1.0, ge=0.0, description="the same, for the rotation of B's assembled pose, degrees")
    look_closer: int = Field(
        2,
        ge=0,
        le=10,
        description="viewpoints a wrist depth camera looks from, at most, when the fixed cameras leave a detection "
        "ambiguous (at detect and at look_again): the arm moves there, senses and comes back, and the rivals are "
        "judged on every view (asmteach.core.pipeline.active_look); 0 switches it off, and so does a robot without a "
        "wrist camera",
    )
    in_hand: Literal["off", "measure", "reaim"] = Field(
        "measure",
        description="the depth cameras' look at a held part before its insertion: 'measure' records it (the "
        "trace's 'measure in hand' event), 'reaim' also re-aims the insertion for it when it is clearly off "
        "(asmteach.core.pipeline.execute.REALIGN_*), 'off' skips it. Measured, re-aiming does not pay: in the "
        "120-trial structures sweep of session 18 it re-aimed 5 insertions (6.6-10.7 deg; 1.3 mm RMSE from the "
        "1 m Kinect against a grasp 0.1-0.7 deg off) and all 5 failed; with 'measure' all 5 assemble "
        "(docs/results/structures_corpus.md, Session 19)",
    )
    fixture: Literal["auto", "never", "always"] = Field(
        "auto",
        description="a jig holds A while B goes in (asmteach.core.arm.fixture): 'auto' when the plan says A at its "
        "goal would slide or tip under the insertion's force limit, 'always', or 'never'; a run that uses one says "
        "'A held by a jig' in its report",
    )

    @field_validator("look_again", mode="before")
    @classmethod
    def _look_again_bool(cls, v: Any) -> Any:
        # configs written before the choice existed said true / false
        return {True: "ambiguous", False: "never"}.get(v, v) if isinstance(v, bool) else v


MAX_SEED = 2**31 - 1
"""Largest seed: libraries seeded from it (Open3D's RANSAC) take a signed 32-bit integer."""


class RunConfig(StrictModel):
    """Top-level config of ``asmteach run`` / ``validate``; paths are relative to the config's folder."""

    name: str = Field("run", description="name of the run (report title, output folder's record)")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="every random choice of the run flows from it")
    structure: str = Field(description="assembly structure YAML (parts A and B, T_A_B, v_a)")
    camera: str | None = Field(None, description="RGB camera intrinsics YAML; default: a C615-like webcam")
    table: TableSettings = Field(default_factory=TableSettings, description="the work table (world frame, metres)")
    teacher: PluginChoice = Field(
        default_factory=lambda: PluginChoice(plugin="aruco"), description="learns T_A_B and v_a (teachers)"
    )
    detector: PluginChoice = Field(
        default_factory=lambda: PluginChoice(plugin="cvfh_icp"), description="finds each part's pose (detectors)"
    )
    corrector: PluginChoice | None = Field(
        default_factory=lambda: PluginChoice(plugin="stable_placements"),
        description="snaps a detected pose to a resting pose (correctors); null: none",
    )
    grasp_planner: PluginChoice = Field(
        default_factory=lambda: PluginChoice(plugin="antipodal"), description="grasps of each part (grasp_planners)"
    )
    motion_planner: PluginChoice = Field(
        default_factory=lambda: PluginChoice(plugin="trrt"), description="collision-free arm paths (motion_planners)"
    )
    robot: PluginChoice = Field(
        default_factory=lambda: PluginChoice(plugin="nextage_pybullet"),
        description="the simulated robot, its sensor and table (robots)",
    )
    assembly_planner: PluginChoice = Field(
        default_factory=lambda: PluginChoice(plugin="regrasp"),
        description="the pick, place and insert plan (assembly_planners)",
    )
    demo: dict[str, Any] = Field(
        default_factory=dict,
        description="settings of the teacher's rendered demonstration, validated by the teacher plugin's "
        "DemoSettings model (`asmteach plugins --settings` lists them)",
    )
    execution: ExecutionSettings = Field(
        default_factory=ExecutionSettings, description="the simulated execution and what counts as success"
    )

    base_dir: Path | None = Field(None, exclude=True, description="folder of the YAML file; set by the loader")

    def path(self, relative: str) -> Path:
        """Resolve a path written in the config against the config's folder."""
        return resolve_relative(relative, self.base_dir or Path.cwd())


ROLE_OF_KEY = {
    "teacher": "teachers",
    "detector": "detectors",
    "corrector": "correctors",
    "grasp_planner": "grasp_planners",
    "motion_planner": "motion_planners",
    "robot": "robots",
    "assembly_planner": "assembly_planners",
}
