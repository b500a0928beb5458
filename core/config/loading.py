"""Loading a run config: YAML (with dotted overrides) into a :class:`RunConfig`, every plugin's settings checked."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from asmteach.core.config.run_config import ROLE_OF_KEY, PluginChoice, RunConfig
from asmteach.core.config.validation import check_finite, format_validation_error, validate_demo, validate_settings
from asmteach.core.errors import UserError
from asmteach.core.io import read_yaml

__all__ = ["check_overrides", "load_run_config", "set_dotted"]


def load_run_config(
    path: str | Path, *, check_plugins: bool = True, overrides: dict[str, Any] | None = None
) -> RunConfig:
    """Read and validate a run config: every section, and with ``check_plugins`` every plugin's settings.

    ``overrides`` maps dotted keys (``"detector.settings.voxel_size"``) to
    values applied before validation (used by sweeps).
    """
    p = Path(path)
    raw = read_yaml(p)
    if not isinstance(raw, dict):
        raise UserError(f"{p}: a config must be a YAML mapping at the top level")
    try:
        cfg = _validate_run_config(raw, overrides, check_plugins=check_plugins)
    except UserError as exc:
        raise UserError(f"{p}: {exc}") from None
    cfg.base_dir = p.resolve().parent
    if check_plugins:
        structure = cfg.path(cfg.structure)
        if not structure.is_file():
            raise UserError(f"{p}: structure: no such file {structure}")
    return cfg


def check_overrides(overrides: dict[str, Any], *, where: str = "params.overrides") -> None:
    """Dotted run-config keys (as ``asmteach run --set``) checked against every section, before any run.

    For an experiment whose run configs are made per trial: the keys are set
    on a config of the default plugins (or those the overrides choose), so a
    misspelt key, in any section or plugin's settings, fails here in one line
    naming ``where``.
    """
    try:
        defaults = RunConfig(structure="checked later.yaml").model_dump(mode="json", include=set(ROLE_OF_KEY))
        _validate_run_config({"structure": "checked later.yaml", **defaults}, overrides, check_plugins=True)
    except UserError as exc:
        raise UserError(f"{where}: {exc}") from None


def _validate_run_config(raw: dict[str, Any], overrides: dict[str, Any] | None, *, check_plugins: bool) -> RunConfig:
    """``raw`` with ``overrides`` set, as a :class:`RunConfig`; with ``check_plugins`` each plugin's settings too."""
    raw = copy.deepcopy(raw)
    for key, value in (overrides or {}).items():
        set_dotted(raw, key, value)
    check_finite(raw)
    try:
        cfg = RunConfig.model_validate(raw)
    except ValidationError as exc:
        raise UserError(format_validation_error(exc)) from None
    if check_plugins:
        check_plugin_choices(cfg)
    return cfg


def set_dotted(tree: dict[str, Any], dotted: str, value: Any) -> None:
    """Set ``tree["a"]["b"]["c"] = value`` for ``dotted == "a.b.c"``, creating mappings."""
    keys = dotted.split(".")
    node = tree
    for k in keys[:-1]:
        nxt = node.get(k)
        if nxt is None:
            nxt = node[k] = {}
        if not isinstance(nxt, dict):
            raise UserError(f"cannot set {dotted}: {k} is not a mapping")
        node = nxt
    node[keys[-1]] = value


def check_plugin_choices(cfg: RunConfig) -> None:
    """Every plugin the config names exists, and its settings (and a teacher's demo) validate by its models.

    :class:`UserError` naming the key path (``detector.plugin: ...``, ``detector.settings.x: ...``).
    """
    from asmteach.core import registry

    for key, role in ROLE_OF_KEY.items():
        choice: PluginChoice | None = getattr(cfg, key)
        if choice is None:
            continue
        try:
            cls = registry.get_class(role, choice.plugin)
        except UserError as exc:
            raise UserError(f"{key}.plugin: {exc}") from None
        validate_settings(cls, choice.settings, where=f"{key}.settings")
        if key == "teacher":
            validate_demo(cls, choice.plugin, cfg.demo)
