"""The rows of ``asmteach plugins --settings``: key, type, default, description."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from asmteach.core.models import StrictModel
from asmteach.core.settings_listing import describe_settings, nested_model


class Inner(StrictModel):
    radius: float = Field(0.01, gt=0.0, description="metres")


class Outer(StrictModel):
    name: str = Field(description="what it is called")
    mode: Literal["fast", "exact"] = "fast"
    box: tuple[float, float] | None = Field(None, description="x, y extent, metres")
    inner: Inner = Field(default_factory=Inner, description="a nested section")
    maybe: Inner | None = None
    flag: bool = True


def test_rows_name_type_default_and_description_with_nested_keys() -> None:
    rows = {r[0]: r[1:] for r in describe_settings(Outer, prefix="x.")}
    assert rows["x.name"] == ("str", "required", "what it is called")
    assert rows["x.mode"] == ("'fast' | 'exact'", '"fast"', "")
    assert rows["x.box"] == ("tuple[float, float] | None", "null", "x, y extent, metres")
    assert rows["x.inner"] == ("Inner", "{}", "a nested section")
    assert rows["x.inner.radius"] == ("float", "0.01", "metres")
    assert rows["x.maybe.radius"][1] == "0.01" and rows["x.flag"][1] == "true"


def test_nested_model_of_a_field_type() -> None:
    assert nested_model(Inner) is Inner and nested_model(Inner | None) is Inner
    assert nested_model(float) is None and nested_model(dict[str, float]) is None
