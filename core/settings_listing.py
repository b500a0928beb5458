"""The settings of a model as rows for people: what ``asmteach plugins --settings`` prints.

Each row is ``(key, type, default, description)``: nested models as dotted
keys (``execution.scene.x_range``), types as written in Python
(``tuple[float, float] | None``), defaults as written in YAML (``true``,
``null``, ``[0.3, 0.44]``), the description as the field declares it (with its
unit).
"""

from __future__ import annotations

import json
import types
import typing
from typing import Annotated, Any, Literal

from pydantic import BaseModel

__all__ = ["describe_settings", "nested_model"]


def _type_name(t: Any) -> str:
    """A readable name of a field's type: ``float``, ``tuple[float, float] | None``, ``'jpg' | 'png'``."""
    origin, args = typing.get_origin(t), typing.get_args(t)
    if origin is Annotated:
        return _type_name(args[0])
    if origin in (typing.Union, types.UnionType):
        return " | ".join(_type_name(a) for a in args)
    if origin is Literal:
        return " | ".join(repr(a) for a in args)
    if origin is not None:
        return f"{getattr(origin, '__name__', str(origin))}[{', '.join(_type_name(a) for a in args)}]"
    if t is type(None):
        return "None"
    return t.__name__ if isinstance(t, type) else str(t).replace("typing.", "")


def nested_model(t: Any) -> type[BaseModel] | None:
    """The model class of a field typed ``Model`` or ``Model | None``; None for any other type."""
    if isinstance(t, type) and issubclass(t, BaseModel):
        return t
    if typing.get_origin(t) in (typing.Union, types.UnionType):
        models = [a for a in typing.get_args(t) if isinstance(a, type) and issubclass(a, BaseModel)]
        return models[0] if len(models) == 1 else None
    return None


def describe_settings(model: type[BaseModel], prefix: str = "") -> list[tuple[str, str, str, str]]:
    """``(key, type, default, description)`` of every setting of ``model``, nested models as dotted keys.

    What ``asmteach plugins --settings`` prints; a field without a default
    says ``required``, one excluded from YAML (set by the loader) is left out.
    """
    rows: list[tuple[str, str, str, str]] = []
    for name, field in model.model_fields.items():
        if field.exclude:
            continue
        key = f"{prefix}{name}"
        nested = nested_model(field.annotation)
        if field.is_required():
            default = "required"
        else:
            value = field.get_default(call_default_factory=True)
            if isinstance(value, BaseModel):  # a section: what differs from its own defaults, e.g. its plugin
                value = value.model_dump(mode="json", exclude_defaults=True)
            try:
                default = json.dumps(_plain(value))
            except TypeError:
                default = repr(value)
        rows.append((key, _type_name(field.annotation), default, " ".join((field.description or "").split())))
        if nested is not None:
            rows += describe_settings(nested, prefix=f"{key}.")
    return rows


def _plain(value: Any) -> Any:
    """A default as written in YAML: arrays as lists, tuples as lists."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    return value
