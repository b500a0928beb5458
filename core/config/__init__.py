"""Run configurations: YAML into pydantic, with errors a person can act on.

Every section of a run config is a strict model (an unknown key is an error):
the top level (:class:`RunConfig`), ``table`` (:class:`TableSettings`),
``execution`` (:class:`ExecutionSettings`, its ``scene`` a
:class:`SceneSettings`), each role's ``settings`` (the
plugin's own ``Settings`` model) and ``demo`` (the teacher plugin's
``DemoSettings`` model). ``asmteach plugins --settings`` lists them all.
Every error is one line giving the key path and the reason, e.g.
``detector.settings.voxel_size: Input should be greater than 0 (got -1)``.

The package, one module a job: :mod:`.run_config` (the sections' models),
:mod:`.validation` (one-line errors, NaN refusal, plugin and demo settings
checks) and :mod:`.loading` (:func:`load_run_config`, overrides).
"""

from __future__ import annotations

from asmteach.core.config.loading import check_overrides, check_plugin_choices, load_run_config, set_dotted
from asmteach.core.config.run_config import (
    MAX_SEED,
    ROLE_OF_KEY,
    ExecutionSettings,
    PluginChoice,
    RunConfig,
    SceneSettings,
    TableSettings,
)
from asmteach.core.config.validation import (
    check_finite,
    check_plugin_settings,
    format_validation_error,
    validate_demo,
    validate_settings,
)

__all__ = [
    "MAX_SEED",
    "ROLE_OF_KEY",
    "ExecutionSettings",
    "PluginChoice",
    "RunConfig",
    "SceneSettings",
    "TableSettings",
    "check_finite",
    "check_overrides",
    "check_plugin_choices",
    "check_plugin_settings",
    "format_validation_error",
    "load_run_config",
    "set_dotted",
    "validate_demo",
    "validate_settings",
]
