"""pluggy hook specifications: observers and extensions of a run.

Many plugins may implement each hook at once (console progress, JSON-lines
logs, reporters). Hook implementations are registered through the entry-point
group ``asmteach.hooks``; the console progress display is one of them.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import Any

import pluggy

from asmteach.core.registry import distribution, entry_points

__all__ = ["PROJECT", "hookimpl", "hookspec", "make_plugin_manager"]

log = logging.getLogger(__name__)

PROJECT = "asmteach"
hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


class Specs:
    """The hook specifications. Every hook is ``asmteach_<verb>_<noun>``."""

    @hookspec
    def asmteach_stage_started(self, stage: str, total: int | None, context: dict[str, Any]) -> None:
        """A pipeline stage began.

        :param stage: stage name (``"teach"``, ``"detect"``, ``"plan"``, ...).
        :param total: number of work items in the stage, if known (for progress bars).
        :param context: run-level facts (output folder, seed, config name).
        """

    @hookspec
    def asmteach_stage_progress(self, stage: str, advance: int, message: str | None) -> None:
        """Work inside a stage advanced by ``advance`` items."""

    @hookspec
    def asmteach_stage_finished(self, stage: str, ok: bool, seconds: float, summary: dict[str, Any]) -> None:
        """A stage ended; ``ok`` is False when it failed, ``summary`` says how."""

    @hookspec
    def asmteach_artefact_written(self, path: Path, kind: str) -> None:
        """A result file was written atomically (``kind``: ``"json"``, ``"png"``, ``"html"``, ...)."""

    @hookspec
    def asmteach_report_ready(self, report: dict[str, Any], out_dir: Path) -> list[Path] | None:
        """A run's report is final; reporters may write extra files and return their paths."""

    @hookspec
    def asmteach_check_part(self, part: Any, out_dir: Path | None) -> list[tuple[str, str, str]]:
        """What this plugin's stage will do with ``part`` (a :class:`~asmteach.core.interfaces.PartModel`).

        :param out_dir: folder for pictures, or ``None`` for none.
        :return: rows ``(stage, level, text)``, ``level`` one of ``"ok"``, ``"warn"``, ``"fail"``;
            the text says what a user can do about it (``asmteach check-part``).
        """

    @hookspec(firstresult=True)
    def asmteach_measure_part(
        self, part: Any, stage: str, seed: int, workdir: Path, options: dict[str, Any]
    ) -> dict[str, Any] | None:
        """Measure ``stage`` on ``part`` for the ``part_corpus`` experiment; ``None`` when not this plugin's stage.

        :param stage: ``"placements"``, ``"grasps"`` or ``"detection"``.
        :param seed: the trial's seed (scenes, drops, samples).
        :param workdir: the trial's folder for artefacts.
        :param options: ``{"scenes": n}`` and the like, from the experiment's params.
        :return: flat JSON-able metrics; the keys each stage must give are read by
            :func:`asmteach.core.corpus_sweep.passed`.
        """

    @hookspec
    def asmteach_add_commands(self, subparsers: argparse._SubParsersAction) -> None:
        """Add CLI sub-commands; set ``func=callable(args) -> int`` as the parser default."""


_HOOK_STATUS: dict[str, tuple[str, str, str | None]] = {}


def hook_errors() -> dict[str, tuple[str, str, str | None]]:
    """``name -> (distribution, version, import error or None)`` of the last load."""
    return dict(_HOOK_STATUS)


def _load_entry_point_hooks(pm: pluggy.PluginManager) -> None:
    """Like ``load_setuptools_entrypoints`` but one broken plugin does not stop the rest."""
    _HOOK_STATUS.clear()
    for ep in entry_points(PROJECT + ".hooks"):
        ident = distribution(ep)
        if pm.get_plugin(ep.name) is not None or pm.is_blocked(ep.name):
            continue
        try:
            pm.register(ep.load(), name=ep.name)
        except Exception as exc:  # noqa: BLE001 - reported by `asmteach plugins`
            _HOOK_STATUS[ep.name] = (*ident, f"{type(exc).__name__}: {exc}")
            log.warning("hook plugin %s failed to load: %s", ep.name, exc)
            continue
        _HOOK_STATUS[ep.name] = (*ident, None)


def make_plugin_manager(*, load_entry_points: bool = True, progress: bool = True) -> pluggy.PluginManager:
    """Hookspecs, then built-in implementations, then entry points, then a pending check."""
    pm = pluggy.PluginManager(PROJECT)
    pm.add_hookspecs(Specs)
    if progress:
        from asmteach.core.progress import ConsoleProgress

        pm.register(ConsoleProgress(), name="console-progress")
    if load_entry_points:
        _load_entry_point_hooks(pm)
    pm.check_pending()
    return pm
