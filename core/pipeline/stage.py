"""A run's state and its stages: each stage timed, announced to the hooks and recorded in the report.

A stage that fails ends the run as a *result* (:class:`StageFailed`): the report records the stage, the
reason, a bug's traceback included, and the cause (:class:`~asmteach.core.failures.FailureCause`).
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from asmteach.core import registry
from asmteach.core.config import ROLE_OF_KEY, ExecutionSettings, RunConfig, validate_settings
from asmteach.core.errors import UserError
from asmteach.core.failures import FailureCause
from asmteach.core.interfaces import PartModel
from asmteach.core.io import describe_os_error, to_jsonable
from asmteach.core.models import RunReport, StageOutcome
from asmteach.core.symmetry import part_symmetries

__all__ = ["Run", "StageFailed", "default_cause"]


class StageFailed(Exception):
    """A stage could not produce its result; the run ends as a recorded failure.

    ``reason`` is for people; ``cause`` is what code and the sweeps branch on, decided where the stage fails from
    structured data (None: the stage's default, :func:`default_cause`).
    """

    def __init__(self, reason: str, details: dict[str, Any] | None = None, cause: FailureCause | None = None) -> None:
        super().__init__(reason)
        self.reason = reason
        self.details = details or {}
        self.cause = cause


def default_cause(stage: str) -> FailureCause:
    """The cause of a stage's failure that names none (an exception other than a :class:`StageFailed` with one)."""
    return FailureCause.TEACH if stage == "teach" else FailureCause.OTHER


class Run:
    """State of one run: config, plugins, outputs, hooks."""

    def __init__(self, cfg: RunConfig, out_dir: Path, pm: Any | None) -> None:
        self.cfg, self.out, self.pm = cfg, Path(out_dir), pm
        self.report = RunReport(config=cfg.model_dump(mode="json"), seed=cfg.seed)
        self._symmetries: dict[str, list[np.ndarray]] = {}
        self.execution: ExecutionSettings = cfg.execution

    def symmetries(self, part: PartModel) -> list[np.ndarray]:
        """The part's symmetry transforms (part frame), computed once per run."""
        if part.name not in self._symmetries:
            self._symmetries[part.name] = part_symmetries(part.mesh, np.asarray(part.center_of_mass, float))
        return self._symmetries[part.name]

    def plugin(self, key: str) -> Any:
        choice = getattr(self.cfg, key)
        cls = registry.get_class(ROLE_OF_KEY[key], choice.plugin)
        return cls(validate_settings(cls, choice.settings, where=f"{key}.settings"), seed=self.cfg.seed)

    def hook(self, name: str, **kwargs: Any) -> Any:
        if self.pm is None:
            return None
        return getattr(self.pm.hook, name)(**kwargs)

    def progress(self, stage: str) -> Callable[[str], None]:
        return lambda msg: self.hook("asmteach_stage_progress", stage=stage, advance=0, message=msg)

    def artefact(self, name: str, path: Path, kind: str) -> None:
        self.report.artefacts[name] = (
            str(Path(path).relative_to(self.out)) if Path(path).is_relative_to(self.out) else str(path)
        )
        self.hook("asmteach_artefact_written", path=Path(path), kind=kind)

    @contextmanager
    def stage(self, name: str, total: int | None = None) -> Iterator[dict[str, Any]]:
        details: dict[str, Any] = {}
        self.hook(
            "asmteach_stage_started",
            stage=name,
            total=total,
            context={"out_dir": str(self.out), "seed": self.cfg.seed, "config": self.cfg.name},
        )
        t0 = time.perf_counter()
        try:
            yield details
        except Exception as exc:  # noqa: BLE001 - any failure of a stage ends the run as a recorded result
            seconds = time.perf_counter() - t0
            cause = default_cause(name)
            if isinstance(exc, StageFailed):
                reason = exc.reason
                details.update(exc.details)
                cause = exc.cause or cause
            elif isinstance(exc, UserError | NotImplementedError):  # bad input; a plugin without an optional method
                reason = str(exc)
            elif isinstance(exc, OSError):  # the file system failed (a full disk): the task failed, no bug
                reason = describe_os_error(exc)
            else:  # a bug or an unforeseen input: the report still says where and why, with the traceback
                reason = f"internal error ({type(exc).__name__}: {exc})"
                details["traceback"] = traceback.format_exc(limit=12)
            self.report.stages.append(
                StageOutcome(
                    stage=name, ok=False, seconds=round(seconds, 3), reason=reason, details=to_jsonable(details)
                )
            )
            self.report.failed_stage, self.report.reason, self.report.failure_cause = name, reason, cause
            self.hook(
                "asmteach_stage_finished",
                stage=name,
                ok=False,
                seconds=seconds,
                summary={"reason": reason, "cause": cause.value},
            )
            raise StageFailed(reason, cause=cause) from None
        seconds = time.perf_counter() - t0
        self.report.stages.append(
            StageOutcome(stage=name, ok=True, seconds=round(seconds, 3), details=to_jsonable(details))
        )
        self.hook(
            "asmteach_stage_finished",
            stage=name,
            ok=True,
            seconds=seconds,
            summary={k: v for k, v in details.items() if isinstance(v, (int, float, str))},
        )
