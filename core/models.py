"""Data contracts shared by every stage, as pydantic v2 models.

All models forbid unknown keys and round-trip through JSON
(``Model.model_validate_json(m.model_dump_json())``). Poses are ``(4, 4)``
numpy arrays inside and 4x4 row-major nested lists in JSON; in hand-written
YAML a pose may also be given as ``{xyz: [m, m, m], rpy_deg: [deg, deg, deg]}``.
Units: metres, radians, kilograms, seconds; millimetres and degrees only in
report fields whose names say so (``*_mm``, ``*_deg``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    PlainSerializer,
    WithJsonSchema,
    field_validator,
    model_validator,
)

from asmteach.core import geometry

__all__ = [
    "AssemblyTask",
    "CameraIntrinsics",
    "Correction",
    "Detection",
    "Grasp",
    "GripperEvent",
    "HandSpec",
    "MarkerSpec",
    "Mat4",
    "PartSpec",
    "Placement",
    "Plan",
    "PlanSegment",
    "Primitive",
    "RunReport",
    "SolidSpec",
    "StageOutcome",
    "StrictModel",
    "TablePlane",
    "TeachingEvidence",
    "Trajectory",
    "Vec3",
]


# ---------------------------------------------------------------- array types
def _finite_array(value: Any, what: str) -> np.ndarray:
    """``value`` as a float array; ``ValueError`` naming ``what`` when it is not numbers or not finite."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be numbers") from None
    if not np.all(np.isfinite(arr)):
        # NaN slips through every comparison (a NaN pose passes the rotation check), so test it first.
        raise ValueError(f"{what} must be finite numbers (no NaN or infinity)")
    return arr


def _to_mat4(value: Any) -> np.ndarray:
    if isinstance(value, dict):
        extra = set(value) - {"xyz", "rpy_deg"}
        if extra:
            raise ValueError(f"a pose given as a mapping takes keys xyz and rpy_deg, not {sorted(extra)}")
        xyz = _finite_array(value.get("xyz", [0.0, 0.0, 0.0]), "xyz")
        rpy_deg = _finite_array(value.get("rpy_deg", [0.0, 0.0, 0.0]), "rpy_deg")
        if xyz.shape != (3,) or rpy_deg.shape != (3,):
            raise ValueError("xyz and rpy_deg need three numbers each")
        return geometry.from_xyz_rpy(xyz, np.radians(rpy_deg))
    return geometry.as_transform(_finite_array(value, "a pose"))


def _to_vec(n: int):
    def convert(value: Any) -> np.ndarray:
        arr = _finite_array(value, "values")
        if arr.shape != (n,):
            raise ValueError(f"expected {n} numbers, got shape {arr.shape}")
        return arr

    return convert


def _to_mat3(value: Any) -> np.ndarray:
    arr = _finite_array(value, "a 3x3 matrix")
    if arr.shape != (3, 3):
        raise ValueError(f"expected a 3x3 matrix, got shape {arr.shape}")
    return arr


def _listify(a: np.ndarray) -> list[Any]:
    return np.asarray(a).tolist()


_MAT4_SCHEMA = {"type": "array", "items": {"type": "array", "items": {"type": "number"}}}
_VEC_SCHEMA = {"type": "array", "items": {"type": "number"}}

Mat4 = Annotated[
    np.ndarray,
    BeforeValidator(_to_mat4),
    PlainSerializer(_listify, return_type=list),
    WithJsonSchema(_MAT4_SCHEMA),
]
"""A rigid transform: ``(4, 4)`` float array; JSON: 4x4 row-major nested list."""

Mat3 = Annotated[
    np.ndarray,
    BeforeValidator(_to_mat3),
    PlainSerializer(_listify, return_type=list),
    WithJsonSchema(_MAT4_SCHEMA),
]
"""A ``(3, 3)`` float matrix (rotation or camera matrix)."""

Vec3 = Annotated[
    np.ndarray,
    BeforeValidator(_to_vec(3)),
    PlainSerializer(_listify, return_type=list),
    WithJsonSchema(_VEC_SCHEMA),
]
"""A ``(3,)`` float vector."""

FloatArray = Annotated[
    np.ndarray,
    BeforeValidator(lambda v: np.asarray(v, dtype=float)),
    PlainSerializer(_listify, return_type=list),
    WithJsonSchema(_VEC_SCHEMA),
]
"""Any float array (shape kept); JSON: nested lists."""


Unit = Annotated[float, Field(ge=0.0, le=1.0)]
"""A number from 0 to 1 (a colour channel); NaN fails the bounds."""


class StrictModel(BaseModel):
    """Base of every asmteach model: unknown keys are errors, arrays allowed."""

    model_config = ConfigDict(extra="forbid", arbitrary_types_allowed=True, validate_assignment=False)


# ---------------------------------------------------------------- parts
class MarkerSpec(StrictModel):
    """An ArUco marker glued to a part face.

    The marker frame is OpenCV's: origin at the marker centre, z out of the
    printed face, x to the right and y up when the marker is read upright; the
    corners, in OpenCV's order, are ``(-s/2, s/2)``, ``(s/2, s/2)``,
    ``(s/2, -s/2)``, ``(-s/2, -s/2)`` with ``s`` the side length.
    """

    dictionary: str = Field("DICT_4X4_50", description="OpenCV predefined dictionary name, e.g. DICT_4X4_50")
    id: int = Field(ge=0, description="marker id within the dictionary")
    size: float = Field(gt=0.0, le=0.5, description="black-square side length in metres")
    T_part_marker: Mat4 = Field(description="pose of the marker frame in the part frame")


class Primitive(StrictModel):
    """A box or a cylinder, placed in the part frame (metres)."""

    shape: Literal["box", "cylinder"]
    size: Vec3 | None = Field(None, description="box extents x, y, z in metres")
    radius: float | None = Field(None, gt=0.0, description="cylinder radius in metres")
    height: float | None = Field(None, gt=0.0, description="cylinder height (along its z) in metres")
    pose: Mat4 = Field(default_factory=lambda: np.eye(4), description="pose of the primitive's centre")

    @model_validator(mode="after")
    def _check_dims(self) -> Primitive:
        if self.shape == "box" and (self.size is None or np.any(self.size <= 0)):
            raise ValueError("a box needs size: [x, y, z] with every extent > 0")
        if self.shape == "cylinder" and (self.radius is None or self.height is None):
            raise ValueError("a cylinder needs radius and height")
        return self


class SolidSpec(StrictModel):
    """Constructive solid: the union of ``add`` minus the union of ``subtract``."""

    add: list[Primitive] = Field(min_length=1)
    subtract: list[Primitive] = Field(default_factory=list)


class PartSpec(StrictModel):
    """A rigid part: its geometry, physical properties and markers.

    Exactly one of ``solid`` (parametric) and ``mesh`` (a file path, resolved
    relative to the YAML file that names it) is given.
    """

    name: str = Field(min_length=1)
    solid: SolidSpec | None = None
    mesh: str | None = Field(None, description="path to an STL/OBJ/PLY mesh")
    mesh_units: Literal["m", "mm"] = Field("m", description="units of the mesh file's coordinates")
    density: float = Field(700.0, gt=0.0, description="kg/m^3; 700 is a hardwood block")
    mass: float | None = Field(None, gt=0.0, description="kg; overrides density * volume")
    center_of_mass: Vec3 | None = Field(None, description="part frame, metres; defaults to the solid's")
    color: tuple[Unit, Unit, Unit] = Field((0.80, 0.62, 0.40), description="RGB, each 0..1")
    markers: list[MarkerSpec] = Field(default_factory=list)

    @model_validator(mode="after")
    def _one_geometry(self) -> PartSpec:
        if (self.solid is None) == (self.mesh is None):
            raise ValueError("give exactly one of solid (parametric) or mesh (a file)")
        ids = [m.id for m in self.markers]
        if len(ids) != len(set(ids)):
            raise ValueError(f"marker ids repeat within part {self.name!r}: {ids}")
        return self


# ---------------------------------------------------------------- teaching
class CameraIntrinsics(StrictModel):
    """Pinhole camera with OpenCV distortion ``(k1, k2, p1, p2[, k3, ...])``."""

    K: Mat3 = Field(description="3x3 camera matrix, pixels")
    dist: list[float] = Field(default_factory=lambda: [0.0] * 5, description="OpenCV distortion coefficients")
    width: int = Field(gt=0, description="image width, pixels")
    height: int = Field(gt=0, description="image height, pixels")

    @field_validator("K")
    @classmethod
    def _focal(cls, K: np.ndarray) -> np.ndarray:
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError(f"the focal lengths fx, fy must be > 0 pixels (got {K[0, 0]:g}, {K[1, 1]:g})")
        return K

    @field_validator("dist")
    @classmethod
    def _finite_dist(cls, d: list[float]) -> list[float]:
        _finite_array(d, "distortion coefficients")
        return d

    @property
    def dist_array(self) -> np.ndarray:
        """Distortion coefficients as a float array (OpenCV's layout)."""
        return np.asarray(self.dist, dtype=float)


class TeachingEvidence(StrictModel):
    """What the teacher saw: frames used and how consistent they were."""

    frames_total: int = 0
    frames_used: list[int] = Field(default_factory=list)
    residuals_px: list[float] = Field(default_factory=list, description="per used frame, RMS reprojection error")
    spread_mm: float | None = Field(None, description="spread (robust std) of the fused translation")
    spread_deg: float | None = Field(None, description="spread of the fused rotation")
    insertion_source: Literal["demonstration", "geometric", "given"] = "given"
    notes: list[str] = Field(default_factory=list)


class AssemblyTask(StrictModel):
    """Two parts and how B sits in A: ``T_A_B`` and the insertion direction ``v_a``.

    ``v_a`` is a unit vector in A's frame along which B moves *into* its
    assembled pose; the pre-assembly pose of B is ``T_A_B`` translated by
    ``-retract * v_a``.
    """

    name: str
    part_a: PartSpec
    part_b: PartSpec
    T_A_B: Mat4
    v_a: Vec3
    evidence: TeachingEvidence | None = None

    @field_validator("v_a")
    @classmethod
    def _unit(cls, v: np.ndarray) -> np.ndarray:
        n = float(np.linalg.norm(v))
        if n < 1e-9:
            raise ValueError("v_a must be a non-zero direction")
        return v / n

    @model_validator(mode="after")
    def _unique_markers(self) -> AssemblyTask:
        a = {m.id for m in self.part_a.markers}
        b = {m.id for m in self.part_b.markers}
        both = sorted(a & b)
        if both:
            raise ValueError(
                f"marker ids {both} are used on both {self.part_a.name!r} and {self.part_b.name!r}; "
                "give each marker of a structure its own id"
            )
        return self


# ---------------------------------------------------------------- execution phase
class TablePlane(StrictModel):
    """The supporting plane: points ``p`` with ``normal . p = height`` (world frame)."""

    height: float = Field(0.0, description="metres along the normal")
    normal: Vec3 = Field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))


class Detection(StrictModel):
    """Result of detecting one part in a depth cloud (world frame, metres)."""

    part: str
    found: bool
    reason: str | None = Field(None, description="why nothing was found; None when found")
    rough: Mat4 | None = Field(None, description="T_world_part from the detector")
    corrected: Mat4 | None = Field(None, description="T_world_part after the corrector")
    fitness: float | None = Field(None, description="ICP inlier fraction; higher is better")
    inlier_rmse: float | None = Field(None, description="metres; lower is better")
    timing_ms: dict[str, float] = Field(default_factory=dict)
    details: dict[str, Any] = Field(default_factory=dict)

    @property
    def best(self) -> np.ndarray | None:
        """The corrected pose when there is one, else the rough one."""
        return self.corrected if self.corrected is not None else self.rough


class Correction(StrictModel):
    """A corrector's output: the corrected pose and the placement it snapped to."""

    T_world_part: Mat4
    placement_id: int | None = None
    details: dict[str, Any] = Field(default_factory=dict)


class Placement(StrictModel):
    """A stable resting pose of a part on a horizontal table at z = 0.

    ``T_table_part`` puts the part on the table (lowest point at z = 0) with
    the placement's canonical yaw; any yaw about the table normal and any
    x, y translation of it are the same placement.
    """

    id: int
    T_table_part: Mat4
    probability: float = Field(ge=0.0, le=1.0)
    margin: float = Field(description="stability margin d / h (dimensionless)")
    support_polygon: FloatArray = Field(description="(n, 2) support polygon in the table frame, metres")
    symmetry_yaws: list[float] = Field(default_factory=lambda: [0.0], description="radians; equivalent yaws")


class HandSpec(StrictModel):
    """A parallel-jaw gripper, in its TCP frame.

    TCP frame: origin midway between the finger pads when closed on an object,
    z along the approach direction (out of the palm, toward the object),
    y along the jaw axis (finger 0 on -y, finger 1 on +y). The palm is a box
    (``palm_center``, ``palm_size``) in the TCP frame. Each finger is a box of
    ``finger_size`` (thickness along y, depth along x, length along z) that
    hangs from the palm's front face (``z = palm_center.z + palm_size.z / 2``)
    along +z, centred on x = 0; at opening ``w`` its inner face is at
    ``y = -+w/2``. The contact pad (``pad_size``: along x, along z) is centred
    on the TCP's z.
    """

    name: str = Field(description="the gripper's name")
    max_width: float = Field(gt=0.0, description="full stroke, metres")
    min_width: float = Field(0.0, ge=0.0, description="narrowest opening, metres")
    finger_size: Vec3 = Field(description="one finger box: thickness along y, depth along x, length along z")
    pad_size: tuple[float, float] = Field(description="contact pad: along x, along z, metres")
    palm_center: Vec3 = Field(description="centre of the palm box in the TCP frame, metres")
    palm_size: Vec3 = Field(description="palm box extents along TCP x, y, z, metres")
    max_force: float = Field(40.0, gt=0.0, description="gripping force, newtons")


class Grasp(StrictModel):
    """A parallel-jaw grasp ``{p0, p1, R}`` in the part frame.

    ``p0``, ``p1`` are the finger contact points (metres); ``R`` is the TCP
    orientation (columns: TCP x, y, z axes in the part frame), with y pointing
    from ``p0`` to ``p1``. The TCP origin is ``(p0 + p1) / 2``.
    """

    id: int
    p0: Vec3
    p1: Vec3
    R: Mat3
    width: float = Field(ge=0.0, description="jaw opening at contact, metres")
    score: float = Field(0.0, description="quality; higher is better")

    @property
    def T_part_tcp(self) -> np.ndarray:
        """``(4, 4)`` pose of the TCP in the part frame."""
        return geometry.from_rotation(self.R, 0.5 * (self.p0 + self.p1))


# ---------------------------------------------------------------- plans
class Trajectory(StrictModel):
    """A time-parametrised joint path: ``positions[i]`` reached at ``times[i]`` (s)."""

    arm: str
    joint_names: list[str]
    times: list[float]
    positions: FloatArray = Field(description="(n, dof) radians")

    @model_validator(mode="after")
    def _shapes(self) -> Trajectory:
        pos = np.atleast_2d(self.positions)
        if pos.shape != (len(self.times), len(self.joint_names)):
            raise ValueError(f"positions shape {pos.shape} != ({len(self.times)}, {len(self.joint_names)})")
        if np.any(np.diff(self.times) < 0):
            raise ValueError("times must not decrease")
        return self


class GripperEvent(StrictModel):
    """Open or close a gripper; ``attach`` names the part that becomes held."""

    arm: str
    action: Literal["open", "close"]
    width: float | None = None
    attach: str | None = None


class PlanSegment(StrictModel):
    """One step of a plan: a motion or a gripper event, with a label."""

    label: str
    trajectory: Trajectory | None = None
    gripper: GripperEvent | None = None
    part: str | None = Field(None, description="the part this step moves or serves (None: not said)")
    kind: str | None = Field(
        None, description="transit, approach, insertion or regrasp for a motion, gripper for a gripper event (the "
        "split of the robot seconds; None: not said)")


class Plan(StrictModel):
    """An assembly plan: keyframes (named configurations) and the segments between them."""

    keyframes: list[dict[str, Any]] = Field(default_factory=list)
    segments: list[PlanSegment] = Field(default_factory=list)
    stats: dict[str, Any] = Field(default_factory=dict)


class StageOutcome(StrictModel):
    """How one pipeline stage ended."""

    stage: str
    ok: bool
    seconds: float = 0.0
    reason: str | None = None
    details: dict[str, Any] = Field(default_factory=dict)


class RunReport(StrictModel):
    """Everything ``asmteach run`` measured, written as ``report.json``."""

    config: dict[str, Any]
    seed: int
    success: bool = False
    failed_stage: str | None = None
    reason: str | None = None
    stages: list[StageOutcome] = Field(default_factory=list)
    task: AssemblyTask | None = None
    detections: list[Detection] = Field(default_factory=list)
    plan_stats: dict[str, Any] = Field(default_factory=dict)
    metrics: dict[str, float] = Field(default_factory=dict)
    robot_seconds: dict[str, float] = Field(
        default_factory=dict,
        description="the robot's clock: seconds of simulated motion executed, total and per kind (transit, "
        "approach, insertion, regrasp); empty when nothing was executed (the plan's own are in plan_stats)")
    computer_seconds: dict[str, float] = Field(
        default_factory=dict, description="the computer's clock: wall seconds per stage, and their total")
    artefacts: dict[str, str] = Field(default_factory=dict)


def resolve_relative(path: str, base_dir: Path) -> Path:
    """Resolve a path written in a YAML file against that file's folder."""
    p = Path(path).expanduser()
    return p if p.is_absolute() else (base_dir / p).resolve()
