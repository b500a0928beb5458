"""The base of every model: :class:`StrictModel` and the numpy array field types.

Poses are ``(4, 4)`` numpy arrays inside and 4x4 row-major nested lists in
JSON; in hand-written YAML a pose may also be given as
``{xyz: [m, m, m], rpy_deg: [deg, deg, deg]}``. Every array must be finite.
"""

from __future__ import annotations

from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, PlainSerializer, WithJsonSchema

from asmteach.core import geometry

__all__ = ["FloatArray", "Mat3", "Mat4", "StrictModel", "Unit", "Vec3", "finite_array"]


def finite_array(value: Any, what: str) -> np.ndarray:
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
        xyz = finite_array(value.get("xyz", [0.0, 0.0, 0.0]), "xyz")
        rpy_deg = finite_array(value.get("rpy_deg", [0.0, 0.0, 0.0]), "rpy_deg")
        if xyz.shape != (3,) or rpy_deg.shape != (3,):
            raise ValueError("xyz and rpy_deg need three numbers each")
        return geometry.from_xyz_rpy(xyz, np.radians(rpy_deg))
    return geometry.as_transform(finite_array(value, "a pose"))


def _to_vec(n: int):
    def convert(value: Any) -> np.ndarray:
        arr = finite_array(value, "values")
        if arr.shape != (n,):
            raise ValueError(f"expected {n} numbers, got shape {arr.shape}")
        return arr

    return convert


def _to_mat3(value: Any) -> np.ndarray:
    arr = finite_array(value, "a 3x3 matrix")
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
