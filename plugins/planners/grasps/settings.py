"""Settings of the ``antipodal`` grasp planner (metres, radians unless named ``*_deg``)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from asmteach.core.models import StrictModel

__all__ = ["AntipodalSettings", "ScoreWeights"]


class ScoreWeights(StrictModel):
    """Weights of the quality terms (each term is in [0, 1]; the score is their weighted sum)."""

    com: float = Field(0.5, ge=0.0, description="grasp axis close to the centre of mass (less torque to resist)")
    alignment: float = Field(0.2, ge=0.0, description="contact normals along the grasp axis (deep in the cone)")
    pad: float = Field(
        0.3,
        ge=0.0,
        description="the worse pad's torsion radius (contact patch, soft pad) over a fully pressed pad's: "
        "patches beat lines, lines beat points",
    )


class AntipodalSettings(StrictModel):
    """Settings of :class:`AntipodalGraspPlanner` (metres, radians unless named ``*_deg``)."""

    mu: float = Field(0.3, gt=0.0, le=2.0, description="Coulomb friction coefficient of the friction-cone test")
    samples: int = Field(600, ge=10, le=100_000, description="area-weighted surface samples")
    facet_centres: bool = Field(True, description="also sample the centre of every planar facet")
    orientations: int = Field(24, ge=1, le=360, description="palm orientations sampled about each grasp axis")
    clearance: float = Field(0.002, ge=0.0, description="free space per side between fingers and part on approach")
    approach_sweep: float = Field(0.03, ge=0.0, description="hand boxes extended backward by this approach path")
    approach_opening: Literal["full", "pre-shaped"] = Field(
        "full",
        description="the hand on its approach: fully open (the Nextage plugin opens the gripper completely before "
        "every approach, in execution and in the plan re-check) or pre-shaped to the width plus clearance a side",
    )
    pad_grid: tuple[int, int] = Field(
        (7, 9), description="pad sample points along the pad's x and z (odd counts put one on the pad centre)"
    )
    compliance: float = Field(
        0.0015,
        gt=0.0,
        le=0.01,
        description="compressible depth of the soft pads (metres): surface within this depth of the first touch "
        "is in contact, and no point of the part may stand further in front of the planned contact's pad plane",
    )
    pad_inset: float = Field(0.0005, ge=0.0, description="pad samples kept this far inside the pad edge")
    edge_margin: float = Field(
        0.004,
        ge=0.0,
        description="set-backs keep the contacts at least this far inside the pad's fingertip edge (metres): a "
        "contact on the very edge of the pad slips off it",
    )
    pad_min_support: float = Field(
        0.0,
        ge=0.0,
        le=1.0,
        description="optional: share of each pad that must be in contact (1.0: pads fully on a face); 0 leaves it "
        "to the contact model, which accepts line and point contacts on curved parts",
    )
    hold_safety: float = Field(
        1.5,
        ge=0.0,
        description="the grasp must bear this multiple of the part's weight and of its moment about the grasp "
        "axis (soft-finger limit surface, friction mu, force hand.max_force per pad); 0 turns the check off",
    )
    min_thickness: float = Field(0.002, gt=0.0, description="walls thinner than this mark a thin shell")
    dedup_distance: float = Field(0.005, ge=0.0, description="TCPs closer than this ...")
    dedup_angle_deg: float = Field(15.0, ge=0.0, le=180.0, description="... and rotations closer than this are one")
    max_grasps: int = Field(
        600,
        ge=1,
        description="keep at most this many; each resting pose of the part can use only those approaching from "
        "above it, about a quarter",
    )
    set_backs: bool = Field(
        True,
        description="also offer each orientation at its shallowest set-back (TCP moved back along -z, at most half "
        "a pad length, in steps of half the pad grid's row spacing); False: pads always centred on the contacts",
    )
    approach_bins: int = Field(
        32, ge=1, le=1000, description="approach directions (part frame) the kept grasps are spread over"
    )
    rest_poses: int = Field(
        24,
        ge=0,
        le=1000,
        description="resting poses of the part (most probable first) that each get, per contact pair, the "
        "orientation approaching most steeply from above, and their own buckets in the selection",
    )
    bridge_poses: int = Field(
        10,
        ge=0,
        le=100,
        description="the most probable resting poses whose pairs (at most 120 deg apart) get grasps approaching "
        "along their bisector, from above in both, to turn the part over with (0: none)",
    )
    weights: ScoreWeights = Field(default_factory=ScoreWeights, description="weights of the grasp score's terms")
    cache: bool = Field(True, description="read and write the on-disk cache")
    cache_dir: str | None = Field(None, description="cache folder; default $ASMTEACH_CACHE_DIR or ~/.cache/asmteach")
