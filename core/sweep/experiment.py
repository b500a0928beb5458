"""Experiment kinds, the experiment file and its grid.

An experiment kind (:class:`Experiment`) is registered in the entry-point
group ``asmteach.experiments``; :func:`load_experiment` reads an experiment
file (:class:`ExperimentFile`) and validates every grid point's params before
any trial runs.
"""

from __future__ import annotations

import abc
import itertools
import json
from importlib import metadata
from pathlib import Path
from typing import Any, ClassVar

from pydantic import Field, ValidationError, field_validator

from asmteach.core.config import MAX_SEED, check_finite, format_validation_error, set_dotted
from asmteach.core.errors import UserError
from asmteach.core.io import read_yaml
from asmteach.core.models import StrictModel, resolve_relative
from asmteach.core.registry import entry_points, load_named

GROUP = "asmteach.experiments"


class Experiment(abc.ABC):
    """Base of an experiment kind.

    Subclasses set ``Params`` (a :class:`StrictModel`) and implement
    :meth:`run_trial`. ``base_dir`` is the experiment file's folder, for
    resolving paths written in params.
    """

    Params: ClassVar[type[StrictModel]]
    """Validated parameters of one trial; grid keys are dotted paths into it."""

    plot_metrics: ClassVar[tuple[str, ...]] = ()
    """Metrics drawn in the generic ``summary.png`` (at most six); empty: the first numeric ones.

    Only used when :meth:`summarize` writes no figure of its own.
    """

    def __init__(self, base_dir: Path) -> None:
        self.base_dir = base_dir

    def path(self, relative: str) -> Path:
        """Resolve a path written in the experiment file."""
        return resolve_relative(relative, self.base_dir)

    @abc.abstractmethod
    def run_trial(self, params: Any, seed: int, workdir: Path) -> dict[str, Any]:
        """Run one trial; return JSON-able metrics (flat ``name -> number/str/bool`` preferred).

        Raise :class:`UserError` (or any exception) to record a failed trial;
        the sweep keeps going. ``workdir`` is a per-trial folder for artefacts.
        """

    def summarize(self, rows: list[dict[str, Any]], out_dir: Path) -> list[Path]:
        """Write kind-specific tables and figures from all rows; return their paths."""
        return []

    def check(self, params: Any) -> None:
        """Check one grid point's params beyond their model (files named in them, plugin names) before any
        trial runs; raise :class:`UserError` naming the key. The default checks nothing more."""
        return None


class ExperimentFile(StrictModel):
    """The YAML schema of an experiment file."""

    experiment: str = Field(description="experiment kind: entry-point name in asmteach.experiments")
    description: str = ""
    params: dict[str, Any] = Field(default_factory=dict)
    grid: dict[str, list[Any]] = Field(default_factory=dict)
    seeds: int | list[int] = Field(1, description="an int N (seeds 0..N-1) or an explicit list")
    workers: int = Field(1, ge=1, le=64)

    @field_validator("seeds")
    @classmethod
    def _seeds(cls, v: int | list[int]) -> int | list[int]:
        # seeds: 0 would plan no trial at all, a negative seed fails in the middle of a trial
        if isinstance(v, int) and v < 1:
            raise ValueError("give a number of seeds >= 1, or a list of seeds")
        if isinstance(v, int) and v > MAX_SEED:
            raise ValueError(f"give at most {MAX_SEED} seeds")
        if isinstance(v, list):
            if not v or any(s < 0 or s > MAX_SEED for s in v):
                raise ValueError(f"give a non-empty list of seeds, each 0 to {MAX_SEED}")
            if len(set(v)) != len(v):
                raise ValueError("a seed is listed twice; each (grid point, seed) is one trial")
        return v

    def seed_list(self) -> list[int]:
        return list(range(self.seeds)) if isinstance(self.seeds, int) else list(self.seeds)


class TrialSpec(StrictModel):
    """One trial: its grid point, seed and stable id."""

    trial_id: str
    point: dict[str, Any]
    seed: int


def experiment_kinds() -> dict[str, metadata.EntryPoint]:
    """Registered experiment kinds by name."""
    return {ep.name: ep for ep in entry_points(GROUP)}


def load_kind(name: str) -> type[Experiment]:
    """The experiment class registered as ``name``; :class:`UserError` if unknown."""
    return load_named(GROUP, name, Experiment, "experiment kind")


def load_experiment(path: str | Path) -> tuple[ExperimentFile, type[Experiment]]:
    """Read and validate an experiment file and every grid point's params."""
    p = Path(path)
    raw = read_yaml(p)
    if not isinstance(raw, dict):
        raise UserError(f"{p}: an experiment file must be a YAML mapping")
    check_finite(raw, str(p))  # a NaN passes every bound of a Params model
    try:
        exp = ExperimentFile.model_validate(raw)
    except ValidationError as exc:
        raise UserError(f"{p}: {format_validation_error(exc)}") from None
    kind = load_kind(exp.experiment)
    checker = kind(p.resolve().parent)
    for point in grid_points(exp):
        # Every grid point is validated before the first trial runs: a typo in the tenth value of a grid
        # costs one line now, not a sweep of failed trials.
        params = params_for(kind, exp, point, where=str(p))
        try:
            checker.check(params)
        except UserError as exc:
            at = ", ".join(f"{k}={v!r}" for k, v in point.items())
            raise UserError(f"{p}: {exc}" + (f" (grid point {at})" if at else "")) from None
    return exp, kind


def grid_points(exp: ExperimentFile) -> list[dict[str, Any]]:
    """Cartesian product of the grid, in file order."""
    keys = list(exp.grid)
    if not keys:
        return [{}]
    return [dict(zip(keys, values, strict=True)) for values in itertools.product(*(exp.grid[k] for k in keys))]


def params_for(kind: type[Experiment], exp: ExperimentFile, point: dict[str, Any], *, where: str = "") -> Any:
    """Validated params of one grid point (base params with the point's keys set)."""
    raw = json.loads(json.dumps(exp.params))
    for key, value in point.items():
        set_dotted(raw, key, value)
    try:
        return kind.Params.model_validate(raw)
    except ValidationError as exc:
        prefix = f"{where}: " if where else ""
        raise UserError(f"{prefix}{format_validation_error(exc, 'params')}") from None
