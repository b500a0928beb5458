"""Plans: timed joint trajectories (seconds, radians), gripper events and the segments they make up."""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator

from asmteach.core.models.base import FloatArray, StrictModel

__all__ = ["GripperEvent", "Plan", "PlanSegment", "Trajectory"]


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
        None,
        description="transit, approach, insertion or regrasp for a motion, gripper for a gripper event (the "
        "split of the robot seconds; None: not said)",
    )


class Plan(StrictModel):
    """An assembly plan: keyframes (named configurations) and the segments between them."""

    keyframes: list[dict[str, Any]] = Field(default_factory=list)
    segments: list[PlanSegment] = Field(default_factory=list)
    stats: dict[str, Any] = Field(default_factory=dict)
