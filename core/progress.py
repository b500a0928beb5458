"""Console progress display: a hook implementation like any other reporter."""

from __future__ import annotations

import sys
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, Progress, TaskID, TextColumn, TimeElapsedColumn

from asmteach.core.hooks import hookimpl

__all__ = ["ConsoleProgress"]


class ConsoleProgress:
    """One progress bar per stage on stderr (stdout stays for results)."""

    def __init__(self, console: Console | None = None) -> None:
        self.console = console or Console(stderr=True, force_terminal=None)
        self._progress: Progress | None = None
        self._tasks: dict[str, TaskID] = {}

    def _bar(self) -> Progress:
        if self._progress is None:
            self._progress = Progress(
                TextColumn("[bold]{task.description:<12}"),
                BarColumn(),
                TextColumn("{task.completed}/{task.total}" if sys.stderr.isatty() else ""),
                TimeElapsedColumn(),
                TextColumn("{task.fields[message]}"),
                console=self.console,
                transient=False,
            )
            self._progress.start()
        return self._progress

    @hookimpl
    def asmteach_stage_started(self, stage: str, total: int | None, context: dict[str, Any]) -> None:
        bar = self._bar()
        self._tasks[stage] = bar.add_task(stage, total=total or 1, message="")

    @hookimpl
    def asmteach_stage_progress(self, stage: str, advance: int, message: str | None) -> None:
        if stage in self._tasks and self._progress is not None:
            self._progress.update(self._tasks[stage], advance=advance, message=message or "")

    @hookimpl
    def asmteach_stage_finished(self, stage: str, ok: bool, seconds: float, summary: dict[str, Any]) -> None:
        if stage in self._tasks and self._progress is not None:
            task = self._progress.tasks[self._tasks[stage]]
            status = "[green]ok" if ok else f"[red]failed: {summary.get('reason', '')}"
            self._progress.update(self._tasks[stage], completed=task.total, message=f"{status} ({seconds:.2f} s)")
            if all(t.finished for t in self._progress.tasks):
                self._progress.stop()
                self._progress = None
                self._tasks.clear()
