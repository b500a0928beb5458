"""Settings of the ``aruco`` teacher (:class:`ArucoTeacherSettings`), the run config's ``teacher.settings``."""

from __future__ import annotations

from pydantic import Field

from asmteach.core.models import StrictModel
from asmteach.plugins.detectors.aruco.detect import RefineMethod

__all__ = ["ArucoTeacherSettings"]


class ArucoTeacherSettings(StrictModel):
    """Settings of the ``aruco`` teacher (lengths in metres, angles in degrees, errors in pixels)."""

    corner_refinement: RefineMethod = Field("edges", description="edges: line fits to the marker's outer edges")
    edge_max_line_rms: float = Field(
        0.25,
        gt=0,
        description="edges: a marker side whose edge points scatter more "
        "than this (pixels RMS) about its line, or more than 2.5 times the edge-point "
        "noise measured on the marker's own sides if that is larger, is not trusted "
        "(marker dropped)",
    )
    edge_min_inliers: float = Field(
        0.85,
        gt=0,
        le=1,
        description="edges: fraction of a side's edge profiles that "
        "must be clean steps (docs/results/real_sensor_data.md, section 2: a real "
        "JPEG's small markers fail this on some sides)",
    )
    marker_reject_px: float = Field(1.0, gt=0, description="drop a marker whose RMS reprojection error exceeds this")
    frame_reject_px: float = Field(1.0, gt=0, description="drop a frame whose RMS reprojection error exceeds this")
    min_frames: int = Field(3, ge=1, description="assembled frames needed (both parts seen)")
    assembled_radius: float = Field(0.004, gt=0, description="B-in-A positions this close form the assembled cluster")
    assembled_angle_deg: float = Field(4.0, gt=0, description="... and rotations this close")
    fusion_k: float = Field(3.0, gt=0, description="outlier threshold of the fusion, robust standard deviations")
    joint_refine: bool = Field(True, description="joint LM adjustment of T_A_B over all kept frames")
    joint_reject_px: float = Field(
        0.3, gt=0, description="joint adjustment drops frames whose RMS exceeds this and four times the median"
    )
    min_approach_frames: int = Field(3, ge=2, description="approach frames needed to learn v_a")
    min_approach_travel: float = Field(0.01, gt=0, description="B must travel this far toward A to learn v_a")
    check_insertion: bool = Field(True, description="check v_a with python-fcl; fall back to geometry if it fails")
    retract: float = Field(0.5, gt=0, description="retreat distance of the check along -v_a, metres")
    snap_cone_deg: float = Field(
        6.0,
        gt=0,
        le=30,
        description="a learned v_a failing the check moves to the free retreat directions within this cone, degrees",
    )
    collision_tolerance: float = Field(5e-4, ge=0, description="meshes shrunk by this for contact checks, metres")
    threads: int | None = Field(None, ge=1, description="detection threads (default: all cores)")
