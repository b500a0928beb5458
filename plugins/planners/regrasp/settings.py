"""Settings of the regrasp planner's part transfers. Distances in metres, angles in radians, times in seconds."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from asmteach.core.models import StrictModel

__all__ = ["AssemblySettings"]


class AssemblySettings(StrictModel):
    """How keyframes and motions are chosen. Distances in metres, angles in radians, times in seconds."""

    retract: float = Field(
        0.05, gt=0.0, le=0.5, description="pre-assembly retraction of B along -v_a, metres; more where B is still in A"
    )
    vertical_snap_deg: float = Field(
        2.0,
        ge=0.0,
        le=10.0,
        description="a taught v_a this close to the normal of one of A's plane faces is made that normal, and one this "
        "close to straight down at A's goal is made straight down, degrees (0: off)",
    )
    goal_xy: tuple[float, float] = Field((0.40, 0.0), description="where A is assembled on the table (world x, y)")
    goal_yaw: float = Field(0.0, description="yaw of A's goal placement about the table normal")
    min_goal_grasps: int = Field(
        3,
        ge=0,
        le=100,
        description="A's goal placement is the one making B's insertion most nearly vertical among those where at "
        "least this many grasps of B are feasible (IK, collision) when assembled; if none, the one with the most "
        "(0: always the most vertical, unchecked)",
    )
    goal_symmetries: int = Field(
        8,
        ge=1,
        le=64,
        description="B's assembled pose and up to this many minus one of its symmetric equivalents (B's symmetry "
        "group: the same solid in the same place) are goals; each is a goal layer of the regrasp graph, so a grasp "
        "need only be feasible at one (1: the taught pose alone)",
    )
    placement_yaws: int = Field(4, ge=1, le=24, description="evenly sampled yaws per stable placement")
    max_placements: int = Field(4, ge=0, le=32, description="most probable placements used as middle layers")
    max_candidates: int = Field(40, ge=1, le=500, description="grasps solved by IK per slot after screening")
    max_candidates_wide: int = Field(
        80,
        ge=1,
        le=1000,
        description="when no keyframe path exists, the search is tried once more with every placement (symmetric "
        "duplicates too) and this many grasps solved per slot",
    )
    relocations: tuple[Annotated[float, Field(gt=0.0, le=1.0)], ...] = Field(
        (0.5, 0.25, 0.75),
        description="when even the widened search finds no keyframe path, every placement is tried again at "
        "these fractions (dimensionless; 0 = start, 1 = goal) of the way from the part's start to its goal on "
        "the table, one position at a time in this order, until a path exists (empty: never)",
    )
    relocation_clearance: float = Field(
        0.03,
        ge=0.0,
        le=0.3,
        description="metres: a relocated placement keeps at least this distance between the part and every "
        "obstacle other than the table (room for the fingers); positions closer are skipped",
    )
    transit_clearance: float = Field(
        0.01,
        ge=0.0,
        le=0.1,
        description="metres: a free motion keeps at least this distance from the table, the parts and the other "
        "arm wherever its two ends have as much (else as much as its closer end has); a path the planner found "
        "closer is planned again with that floor, and kept only if no path with it is found (the motion's "
        "least clearance is in the stats); room for the arm lagging its path and a part shifted in the hand. "
        "0 turns it off",
    )
    min_down: float = Field(0.3, ge=-1.0, le=1.0, description="cosine: approach to a part on the table from above")
    min_down_last: float = Field(
        0.0,
        ge=-1.0,
        le=1.0,
        description="cosine: when even the relocated placements give no keyframe path, every layer is screened "
        "once more with this bound on the approach to a part on the table (0: from the side too, never from "
        "below; the hand's sweep is still checked against the table); at or above min_down: never",
    )
    pregrasp_distance: float = Field(0.06, gt=0.0, description="approach stand-off along the TCP -z")
    lift: float = Field(0.08, gt=0.0, description="lift above the table after grasping / before placing")
    release_gap: float = Field(
        0.001,
        ge=0.0,
        le=0.01,
        description="a part placed on the table is let go this far above it (pressing it down makes it shift)",
    )
    cartesian_step: float = Field(0.004, gt=0.0, description="TCP step of straight-line motions")
    regrasp_penalty: float = Field(10.0, ge=0.0, description="graph weight of one regrasp")
    motion_weight: float = Field(1.0, ge=0.0, description="graph weight per radian of joint motion")
    motion_time_limit: float = Field(
        5.0,
        gt=0.0,
        description="seconds per motion query: a wall-clock safety cap (the planner's iteration limit is the "
        "budget); a query it cuts is listed in the part's stats under wall_clock_cuts",
    )
    max_attempts: int = Field(
        40,
        ge=1,
        description="per part: keyframe sequences tried (each after the last one's motion failed) before giving "
        "up; counted, so the same seed gives the same plan however loaded the machine is",
    )
    time_budget: float = Field(
        600.0,
        gt=0.0,
        description="seconds per part: a wall-clock safety cap on the re-searches after max_attempts; when it "
        "cuts the search, the reason and wall_clock_cuts say so",
    )
    acceleration: float = Field(2.0, gt=0.0, description="joint acceleration limit of the timed paths, rad/s^2")
    timing: Literal["toppra", "trapezoid"] = Field(
        "toppra",
        description="time parametrisation of each motion: 'toppra' once through all its waypoints (corners blended "
        "within 5 mrad, stops only at its ends), 'trapezoid' rest-to-rest at every waypoint (the old timing)",
    )
    insertion_speed: float = Field(
        0.03, gt=0.0, le=0.2, description="TCP speed of the straight insertion with the toppra timing, m/s"
    )
