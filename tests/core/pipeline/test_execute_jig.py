"""The execute stage's jig decision (core/pipeline/execute._jig): made once per plan that inserts, from
``execution.fixture`` and the plan's ``a_under_insertion``; recorded in the stage's details and the metrics."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from asmteach.core.models import Plan, PlanSegment
from asmteach.core.pipeline.execute import _jig

SLIDES = {"holds": False, "summary": "slides under 20.0 N along (-1.00, +0.00, +0.00)"}


def _run(mode: str) -> SimpleNamespace:
    task = SimpleNamespace(part_a=SimpleNamespace(name="block"), part_b=SimpleNamespace(name="slider"))
    return SimpleNamespace(report=SimpleNamespace(task=task, metrics={}), execution=SimpleNamespace(fixture=mode))


def _plan(kind: str, load: dict | None) -> Plan:
    return Plan(
        segments=[PlanSegment(label="insert slider at assembled", kind=kind)], stats={"a_under_insertion": load}
    )


@pytest.mark.parametrize(("mode", "held"), [("auto", "block"), ("always", "block"), ("never", None)])
def test_a_plan_whose_a_slides_holds_it_unless_never(mode: str, held: str | None) -> None:
    run, details = _run(mode), {}
    assert _jig(run, _plan("insertion", SLIDES), details) == held  # type: ignore[arg-type]
    assert run.report.metrics["a_held_by_jig"] == float(held is not None)
    assert "slides under 20.0 N" in details["jig"]


def test_a_plan_without_an_insertion_decides_nothing() -> None:
    run, details = _run("always"), {}
    assert _jig(run, _plan("transit", SLIDES), details) is None  # type: ignore[arg-type]
    assert details == {} and run.report.metrics == {}


def test_an_a_that_resists_is_not_held_and_nothing_is_said() -> None:
    run, details = _run("auto"), {}
    assert _jig(run, _plan("insertion", {"holds": True, "summary": "stays"}), details) is None  # type: ignore[arg-type]
    assert details == {} and run.report.metrics["a_held_by_jig"] == 0.0
