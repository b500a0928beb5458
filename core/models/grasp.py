"""The gripper (a parallel jaw, in its TCP frame) and its grasps of a part (part frame, metres)."""

from __future__ import annotations

import numpy as np
from pydantic import Field

from asmteach.core import geometry
from asmteach.core.models.base import Mat3, StrictModel, Vec3

__all__ = ["Grasp", "HandSpec"]


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
