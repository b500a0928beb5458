"""Plugin discovery through one entry-point group per role.

Built-in plugins are registered in ``pyproject.toml`` under the same groups a
third-party package uses (``asmteach.detectors``, ``asmteach.robots``, ...).
A plugin that fails to import is reported with its error; the others keep
working.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from importlib import metadata
from typing import Any

from asmteach.core.errors import UserError
from asmteach.core.interfaces import ROLES, Plugin

__all__ = [
    "PluginInfo",
    "closest",
    "create",
    "discover",
    "distribution",
    "entry_points",
    "get_class",
    "group_name",
    "load_named",
]

GROUP_PREFIX = "asmteach."


def group_name(role: str) -> str:
    """Entry-point group of a role: ``"detectors"`` -> ``"asmteach.detectors"``."""
    return GROUP_PREFIX + role


@dataclass
class PluginInfo:
    """One discovered entry point, loaded or not."""

    role: str
    name: str
    value: str
    distribution: str
    version: str
    cls: type[Plugin] | None = None
    error: str | None = None


def entry_points(group: str) -> list[metadata.EntryPoint]:
    """The entry points of one whole group name (``"asmteach.hooks"``), sorted by name.

    The one place the project reads entry points: plugin roles, hook plugins and
    experiment kinds all go through it.
    """
    return sorted(metadata.entry_points(group=group), key=lambda ep: ep.name)


def distribution(ep: metadata.EntryPoint) -> tuple[str, str]:
    """``(name, version)`` of the package that registered ``ep`` (``"?"`` when unknown)."""
    dist = ep.dist
    return (dist.metadata["Name"], dist.version) if dist is not None else ("?", "?")


def load_named(group: str, name: str, base: type, what: str) -> type:
    """The class registered as ``name`` in ``group``, a subclass of ``base``.

    ``what`` names the kind of thing in the one-line :class:`UserError` raised when
    the name is unknown (with the closest known name), fails to import, or is not a
    ``base`` subclass.
    """
    eps = {ep.name: ep for ep in entry_points(group)}
    if name not in eps:
        hint = closest(name, list(eps))
        known = ", ".join(sorted(eps)) or "none installed"
        suggestion = f"; did you mean {hint!r}?" if hint else f" (known: {known})"
        raise UserError(f"no {what} named {name!r}{suggestion}")
    try:
        cls = eps[name].load()
    except Exception as exc:
        raise UserError(f"{what} {name!r} ({eps[name].value}) failed to import: {type(exc).__name__}: {exc}") from exc
    if not (isinstance(cls, type) and issubclass(cls, base)):
        raise UserError(f"{what} {name!r} ({eps[name].value}) is not a {base.__name__} subclass")
    return cls


def discover(role: str | None = None, *, load: bool = True) -> list[PluginInfo]:
    """List the plugins of one role (or all roles), loading each unless ``load=False``."""
    roles = [role] if role else list(ROLES)
    out: list[PluginInfo] = []
    for r in roles:
        if r not in ROLES:
            raise UserError(f"unknown plugin role {r!r}; roles are {', '.join(ROLES)}")
        for ep in entry_points(group_name(r)):
            dist_name, version = distribution(ep)
            info = PluginInfo(role=r, name=ep.name, value=ep.value, distribution=dist_name, version=version)
            if load:
                try:
                    cls = ep.load()
                    if not (isinstance(cls, type) and issubclass(cls, ROLES[r])):
                        raise TypeError(f"{ep.value} is not a subclass of {ROLES[r].__name__}")
                    info.cls = cls
                except Exception as exc:  # noqa: BLE001 - reported per plugin, others keep working
                    info.error = f"{type(exc).__name__}: {exc}"
            out.append(info)
    return out


def closest(name: str, choices: list[str]) -> str | None:
    """The known name most like ``name``, if any is close."""
    match = difflib.get_close_matches(name, choices, n=1, cutoff=0.4)
    return match[0] if match else None


def get_class(role: str, name: str) -> type[Plugin]:
    """Load the plugin class ``name`` of ``role``; :class:`UserError` if unknown or broken."""
    if role not in ROLES:
        raise UserError(f"unknown plugin role {role!r}; roles are {', '.join(ROLES)}")
    return load_named(group_name(role), name, ROLES[role], f"{role[:-1].replace('_', ' ')} plugin")


def create(role: str, name: str, settings: dict[str, Any] | None = None, *, seed: int = 0) -> Plugin:
    """Build plugin ``name`` of ``role`` with validated ``settings``."""
    from asmteach.core.config import validate_settings

    cls = get_class(role, name)
    model = validate_settings(cls, settings or {}, where=f"{role}.{name}.settings")
    return cls(model, seed=seed)
