"""Validation errors as one line a person can act on, and the checks of plugin and demo settings.

Every error names the key path and the reason, e.g.
``detector.settings.voxel_size: Input should be greater than 0 (got -1)``.
"""

from __future__ import annotations

import math
from typing import Any

from pydantic import BaseModel, ValidationError

from asmteach.core.errors import UserError
from asmteach.core.interfaces import Plugin, Teacher

__all__ = [
    "MAX_ECHO",
    "check_finite",
    "check_plugin_settings",
    "format_validation_error",
    "validate_demo",
    "validate_settings",
]


def _fmt_loc(loc: tuple[Any, ...]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


MAX_ECHO = 40
"""Longest input value quoted back in an error; a longer text is described, never printed (it may be a file's
contents read by mistake, such as ``--hand /etc/passwd``)."""


def _echo(value: Any) -> str:
    """``value`` for an error message: short values as written, long texts by their length only."""
    if hasattr(value, "tolist") and not isinstance(value, str | bytes):  # a numpy array: as the numbers written
        value = value.tolist()
    if isinstance(value, str | bytes) and (len(value) > MAX_ECHO or "\n" in str(value)):
        return f"a text of {len(value)} characters"
    text = repr(value)
    return text if len(text) <= MAX_ECHO else f"a {type(value).__name__}"


_KIND = {
    "str": "a text",
    "int": "a number",
    "float": "a number",
    "bool": "true/false",
    "list": "a list",
    "NoneType": "nothing (null)",
}
"""How a value read from YAML is named in an error, by its Python type."""


def format_validation_error(exc: ValidationError, prefix: str = "") -> str:
    """First error of a pydantic ``ValidationError`` as ``key.path: reason (got value)``."""
    lines = []
    # A misspelt key also makes the key it was meant to be "missing": the unknown key is the cause, said first.
    for err in sorted(exc.errors(), key=lambda e: e["type"] != "extra_forbidden"):
        loc = _fmt_loc(tuple(p for p in err["loc"] if not (isinstance(p, str) and p.startswith("function-"))))
        path = ".".join(x for x in (prefix, loc) if x)
        msg = err["msg"]
        if err["type"] == "extra_forbidden":
            msg = "unknown key (not a setting of this section; check the spelling)"
        elif err["type"] == "missing":
            at = err["loc"][-1] if err["loc"] else None
            msg = (
                f"too few values (item [{at}] is missing)"
                if isinstance(at, int) and not isinstance(at, bool)
                else "required key is missing"
            )
        elif err["type"] in ("model_type", "dict_type", "model_attributes_type"):
            # the whole section (or file) is not a mapping; its text is not echoed
            got = _KIND.get(type(err.get("input")).__name__, f"a {type(err.get('input')).__name__}")
            msg = f"expected a mapping of keys and values, got {got}"
        elif "input" in err and not isinstance(err["input"], dict | list):
            msg = f"{msg} (got {_echo(err['input'])})"
        msg = msg.removeprefix("Value error, ")
        lines.append(f"{path}: {msg}" if path else msg)  # a check of the whole section speaks for itself
    more = f" (and {len(lines) - 1} more)" if len(lines) > 1 else ""
    return lines[0] + more


def check_finite(tree: Any, where: str = "") -> None:
    """:class:`UserError` naming the key path of the first NaN or infinity in a tree read from YAML.

    YAML writes them ``.nan`` / ``.inf``; no setting of asmteach takes one, and
    a NaN passes every ``>``/``<`` bound check unnoticed, so they are refused
    wherever they are (plugin settings included).
    """

    def walk(node: Any, path: str) -> str | None:
        if isinstance(node, float) and not math.isfinite(node):
            return path or "<root>"
        items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
        for k, v in items:
            sub = f"{path}[{k}]" if isinstance(k, int) else ".".join(x for x in (path, str(k)) if x)
            found = walk(v, sub)
            if found is not None:
                return found
        return None

    bad = walk(tree, "")
    if bad is not None:
        prefix = f"{where}: " if where else ""
        raise UserError(f"{prefix}{bad}: not a finite number (NaN or infinity); write a number")


def validate_settings(cls: type[Plugin], settings: dict[str, Any], *, where: str) -> BaseModel:
    """Validate ``settings`` with the plugin's own model; :class:`UserError` names the key path."""
    try:
        return cls.Settings.model_validate(settings)
    except ValidationError as exc:
        raise UserError(format_validation_error(exc, where)) from None


def check_plugin_settings(role: str, name: str, settings: dict[str, Any], *, name_key: str, settings_key: str) -> None:
    """Plugin ``name`` of ``role`` exists and ``settings`` pass its model; :class:`UserError` naming the key.

    For settings an experiment's params carry for a plugin it builds per trial (checked up front, in
    ``Experiment.check``, like a run config's).
    """
    from asmteach.core import registry

    try:
        cls = registry.get_class(role, name)
    except UserError as exc:
        raise UserError(f"{name_key}: {exc}") from None
    validate_settings(cls, settings, where=settings_key)


def validate_demo(teacher: type[Teacher], name: str, demo: dict[str, Any]) -> BaseModel | None:
    """The ``demo`` section validated by the teacher's ``DemoSettings`` model; None if the teacher has none.

    A teacher that renders demonstrations declares the model of their
    settings as :attr:`Teacher.DemoSettings <asmteach.core.interfaces.Teacher.DemoSettings>`
    (as it declares ``Settings``); a ``demo`` section given to a teacher
    without one is an error, not ignored.
    """
    model = teacher.DemoSettings
    if model is None:
        if demo:
            raise UserError(
                f"demo: the teacher plugin {name!r} takes no demo settings (it renders no "
                "demonstration); remove the demo section"
            )
        return None
    try:
        return model.model_validate(demo)
    except ValidationError as exc:
        raise UserError(format_validation_error(exc, "demo")) from None
