"""The base of every plugin: validated settings and the run's seed.

A plugin is a subclass of one of the roles (:mod:`asmteach.core.interfaces`), registered under the
role's entry-point group (see :mod:`asmteach.core.registry`). Each plugin declares its own pydantic
``Settings`` model (unknown keys forbidden); the registry builds it as ``PluginClass(settings, seed=seed)``.
"""

from __future__ import annotations

import abc
from typing import Any, ClassVar

import numpy as np

from asmteach.core.models import StrictModel

__all__ = ["NoSettings", "Plugin"]


class NoSettings(StrictModel):
    """Settings of a plugin that takes none."""


class Plugin(abc.ABC):  # noqa: B024 - abstract by intent; roles add the abstract methods
    """Base of every plugin: holds validated settings and the run's seed."""

    Settings: ClassVar[type[StrictModel]] = NoSettings
    """The plugin's own settings model; override in subclasses."""

    def __init__(self, settings: StrictModel | dict[str, Any] | None = None, *, seed: int = 0) -> None:
        if settings is None:
            settings = {}
        if isinstance(settings, dict):
            settings = self.Settings.model_validate(settings)
        self.settings = settings
        self.seed = int(seed)

    def rng(self, *salt: int) -> np.random.Generator:
        """A generator derived from the run seed (plus optional salt), never global state."""
        return np.random.default_rng([self.seed, *salt])
