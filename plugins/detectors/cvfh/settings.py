"""Settings of the ``cvfh_icp`` detector (:class:`CvfhSettings`, shown by ``asmteach plugins --settings``)."""

from __future__ import annotations

from pydantic import Field

from asmteach.core.models import StrictModel, Vec3
from asmteach.core.perception.depth_camera import KinectSettings
from asmteach.core.perception.registration import RefineSettings
from asmteach.core.perception.segmentation import SegmentSettings
from asmteach.plugins.detectors.cvfh.views import DescriptorSettings, ViewSettings

__all__ = ["CvfhSettings"]


class CvfhSettings(StrictModel):
    """Settings of the ``cvfh_icp`` detector."""

    viewpoint: Vec3 | None = Field(
        None,
        description="camera centre in the world frame, metres, when detect() is not given one (the CVFH "
        "viewpoint component and the verification's rays need it); no default: a wrong camera rejects every pose",
    )
    segment: SegmentSettings = Field(
        default_factory=SegmentSettings, description="table plane removal and clustering of what stands on it"
    )
    descriptors: DescriptorSettings = Field(
        default_factory=DescriptorSettings,
        description="how views and scene clusters are described (CVFH regions and CRH, the same for both)",
    )
    views: ViewSettings = Field(
        default_factory=ViewSettings, description="the training views rendered around the part (the view database)"
    )
    camera: KinectSettings = Field(default_factory=KinectSettings, description="the camera that renders the views")
    refine: RefineSettings = Field(
        default_factory=RefineSettings, description="point-to-plane ICP and the verification's thresholds"
    )
    nn_views: int = Field(10, ge=1, le=42, description="nearest views (by CVFH distance) turned into hypotheses")
    max_rolls: int = Field(3, ge=1, le=8, description="CRH correlation peaks tried per view (plus their half turns)")
    blind_rolls: int = Field(12, ge=1, description="rolls tried, evenly spaced, when a CRH is undefined")
    icp_candidates: int = Field(10, ge=1, description="hypotheses given a coarse ICP after pre-scoring")
    coarse_points: int = Field(250, ge=20, description="cluster points used by the coarse ICP")
    verify_candidates: int = Field(
        4, ge=1, description="best coarse results given a fine ICP and verification (until two are accepted)"
    )
    max_rounds: int = Field(3, ge=1, description="rounds of icp_candidates hypotheses tried until one verifies")
    max_clusters: int = Field(3, ge=1, description="largest plausible clusters tried, biggest first")
    resting_poses: int = Field(
        8, ge=0, description="most likely stable rests tried when no CVFH hypothesis verifies (0: never)"
    )
    resting_yaws: int = Field(24, ge=1, description="yaws per stable rest, evenly spaced")
    resting_rounds: int = Field(
        8,
        ge=1,
        description="rounds of icp_candidates resting hypotheses tried until one verifies: they are many (rests x "
        "yaws) and a part seen end-on ranks the right yaw low, since every yaw explains the face it shows",
    )
    rest_snap_deg: float = Field(
        10.0,
        ge=0.0,
        description="a refined pose verification rejects that is within this many degrees of one of the "
        "part's stable rests (resting_poses of them) is verified again snapped onto that rest, on the table: "
        "a part seen only above segment.min_height leaves ICP free to tilt (a U bracket 15 mm tall, its legs "
        "half cut off: 7.7 deg off, rejected; at the rest 0.4 deg) (0: never)",
    )
    rest_rivals_deg: float = Field(
        45.0,
        ge=0.0,
        description="poses the view cannot tell apart (near twins, an unpinned turn) are each put at every stable "
        "rest (resting_poses of them) within this many degrees and verified there: when the verified resting poses "
        "are one pose, the table has told them apart (a D peg lying on its flat, rolled about its axis, sinks an "
        "edge into the table) and it is found (0: never)",
    )
    twin_fit: float = Field(0.004, gt=0.0, description="a pose explains a point within this along its ray, metres")
    twin_off: float = Field(0.010, gt=0.0, description="a pose clearly fails a point beyond this along its ray")
    twin_min_points: int = Field(10, ge=1, description="points of evidence needed to tell hull twins apart")
    twin_ratio: float = Field(
        4.0, ge=1.0, description="the evidence against the loser must exceed that against the winner this many times"
    )
    size_slack: float = Field(1.25, ge=1.0, description="a cluster wider than this times the part's is skipped")
    near_twin_tol: float = Field(
        0.002,
        ge=0.0,
        description="a turn keeping the part's surface within this mean distance (metres) of itself is a near twin "
        "whose pose must score clearly worse than the found one (0: no near-twin check)",
    )
    ambiguity_margin: float = Field(
        0.02,
        ge=0.0,
        description="a distinct verified pose scoring within this of the best makes the view ambiguous: found "
        "false (measured on 49 corpus parts: wrong near-twin poses score within 0.007 of the right one, views that "
        "tell them apart put the right one ahead by >= 0.026)",
    )
    nudge_deg: float = Field(
        10.0, ge=0.0, description="the found pose is also tried turned by this about each principal axis (0: not)"
    )
    near_screen_iterations: int = Field(
        10,
        ge=0,
        description="near twins and nudges: a short coarse ICP (this many iterations, on the coarse subsample) "
        "first; a turned pose it brings within half of distinct_mm / distinct_deg of a pose already tried gets no "
        "full ICP (0: every turned pose gets the full ICP)",
    )
    near_fit: float = Field(0.003, gt=0.0, description="near twins: a pose explains a point within this along its ray")
    near_off: float = Field(0.006, gt=0.0, description="near twins: a pose clearly fails a point beyond this")
    distinct_mm: float = Field(5.0, gt=0.0, description="poses farther apart than this (mm) are distinct")
    distinct_deg: float = Field(5.0, gt=0.0, description="poses turned further apart than this (deg) are distinct")
    same_surface: float = Field(
        0.0005,
        ge=0.0,
        description="two poses that put the part's surface in the same place within this (metres, after a shift "
        "of at most distinct_mm) are the same answer, whatever their turn: a tessellated torus or ball turned "
        "by a symmetry the listed ones miss (asmteach.core.symmetry.near; 0: the listed symmetries only)",
    )
    thin_height: float = Field(
        0.014,
        ge=0.0,
        description="a part whose oriented bounding box is thinner than this (metres) may lie mostly below "
        "segment.min_height: its points lower than that are kept where the mean height of their patch stands "
        "clearly above the table (cvfh/thin.py; 0: never)",
    )
    thin_cell: float = Field(0.003, gt=0.0, description="thin parts: side of the patch squares, metres")
    thin_sigmas: float = Field(
        6.0,
        gt=0.0,
        description="thin parts: a patch is raised when its mean height exceeds the table's by this many spreads "
        "of the patch means (measured on the frame)",
    )
    pin_sigmas: float = Field(
        3.0,
        ge=0.0,
        description="the found pose's rotation uncertainty (one sigma in its weakest direction, from the seen "
        "points and the Kinect's noise) times this must stay within distinct_deg, else the view does not pin "
        "the pose down and it is not reported (0: no check)",
    )
    pin_same: float = Field(
        0.0005,
        gt=0.0,
        description="a turn mapping the part's surface onto itself within this (metres) is a symmetry, not "
        "checked by pin_sigmas (the tolerance of asmteach.core.symmetry.equivalent_transforms)",
    )
