"""The regrasp planner's ``timing`` and ``insertion_speed`` settings reach the time parametrisation."""

from __future__ import annotations

from typing import Any

import pytest
from pydantic import ValidationError

from asmteach.plugins.planners.regrasp import planner as planner_module
from asmteach.plugins.planners.regrasp.planner import RegraspAssemblyPlanner
from asmteach.plugins.planners.regrasp.settings import AssemblySettings


@pytest.mark.parametrize("timing", ["toppra", "trapezoid"])
def test_the_configured_timing_and_insertion_speed_are_what_the_plan_is_timed_with(monkeypatch, timing: str) -> None:
    seen: dict[str, Any] = {}

    def fake_to_plan(steps: Any, robot: Any, acceleration: float, **kwargs: Any) -> Any:
        seen.update(kwargs, acceleration=acceleration)
        return planner_module.Plan()

    monkeypatch.setattr(planner_module, "to_plan", fake_to_plan)
    planner = RegraspAssemblyPlanner(AssemblySettings(timing=timing, insertion_speed=0.05, acceleration=1.5))
    planner._timed(robot=None, parts=[], t0=0.0)
    assert (seen["timing"], seen["insertion_speed"], seen["acceleration"]) == (timing, 0.05, 1.5)


def test_an_unknown_timing_is_refused_naming_the_choices() -> None:
    with pytest.raises(ValidationError, match="toppra"):
        AssemblySettings(timing="spline")
