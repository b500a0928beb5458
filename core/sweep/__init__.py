"""Experiment sweeps: parameter grids x seeds, resumable, parallel.

An *experiment kind* is a class registered in the entry-point group
``asmteach.experiments``. It declares a pydantic ``Params`` model, runs one
trial from validated params and a seed, and may summarise all rows into
tables and plots. An *experiment file* (YAML) picks the kind and the grid::

    experiment: teaching_precision     # entry-point name
    params: {frames: 30}               # base params (validated by the kind's Params)
    grid:                              # cartesian product over dotted keys of params
      distance: [0.35, 0.5, 0.8]
    seeds: 3                           # an int N (seeds 0..N-1) or a list
    workers: 2                         # local processes (default: 1)

``asmteach sweep FILE --out DIR`` appends one JSON line per finished trial to
``DIR/trials.jsonl`` (fsynced), skips trials already there when re-run, and
writes ``trials.csv``, ``summary.csv``, ``summary.md`` and the kind's own
figures atomically; a kind that draws no figure of its own gets the generic
``summary.png`` (each numeric metric against the grid key with most values).

Ctrl-C: the first one stops starting trials and waits for those in flight,
recording them, so nothing computed is lost (the Ray executor cancels its
trials in flight instead); a second one abandons the trials in flight. Either
way ``trials.jsonl`` stays valid and a re-run does exactly the missing trials.
A hard crash can tear the last line, which readers skip.

The package, one module a job: :mod:`.experiment` (experiment kinds, the
experiment file and its grid), :mod:`.trials` (trial ids and what a resume
keeps), :mod:`.executors` (running trials: serial, process pool, Ray; Ctrl-C
and workers that die with the sweep), :mod:`.run` (:func:`run_sweep` and the
``asmteach sweep`` command), :mod:`.summary` (tables) and :mod:`.plot` (the
generic figure).
"""

from __future__ import annotations

from asmteach.core.sweep.experiment import (
    GROUP,
    Experiment,
    ExperimentFile,
    TrialSpec,
    experiment_kinds,
    grid_points,
    load_experiment,
    load_kind,
    params_for,
)
from asmteach.core.sweep.plot import (
    IMAGE_SUFFIXES,
    plot_axis_key,
    plot_columns,
    series_stats,
    summary_figure,
    summary_plot,
)
from asmteach.core.sweep.run import add_sweep_command, run_sweep
from asmteach.core.sweep.summary import flatten, group_table, summarize, to_csv, to_markdown
from asmteach.core.sweep.trials import current_rows, params_hash, plan_trials, trial_id

__all__ = [
    "GROUP",
    "IMAGE_SUFFIXES",
    "Experiment",
    "ExperimentFile",
    "TrialSpec",
    "add_sweep_command",
    "current_rows",
    "experiment_kinds",
    "flatten",
    "grid_points",
    "group_table",
    "load_experiment",
    "load_kind",
    "params_for",
    "params_hash",
    "plan_trials",
    "plot_axis_key",
    "plot_columns",
    "run_sweep",
    "series_stats",
    "summarize",
    "summary_figure",
    "summary_plot",
    "to_csv",
    "to_markdown",
    "trial_id",
]
