"""Trial ids and resume: which trials an experiment plans, and which logged rows are theirs.

A trial's id hashes its grid point, seed and resolved params (and the files
those params name), so a resumed sweep skips exactly the trials already run
under the same params.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from asmteach.core.models import resolve_relative
from asmteach.core.sweep.experiment import Experiment, ExperimentFile, TrialSpec, grid_points, params_for


def params_hash(kind_name: str, params: Any, base_dir: Path | None = None) -> str:
    """Hash of a trial's resolved params (every value, defaults included) and its experiment kind.

    With ``base_dir`` (the experiment file's folder), a text param naming a
    file there (``run_config: ../demo.yaml``) adds the file's contents: a
    run config edited between two runs of a sweep is other params too. One
    level only: the files such a file names in turn are not read.
    """
    resolved = params.model_dump(mode="json") if hasattr(params, "model_dump") else params
    files: dict[str, str] = {}
    if base_dir is not None:
        for value in _texts(resolved):
            if len(value) < 4096 and "\n" not in value:
                try:
                    path = resolve_relative(value, base_dir)
                    if path.is_file() and path.stat().st_size < 16_000_000:
                        files[value] = hashlib.sha1(path.read_bytes()).hexdigest()
                except (OSError, ValueError):
                    continue
    blob = json.dumps(
        {"kind": kind_name, "params": resolved, **({"files": files} if files else {})}, sort_keys=True, default=str
    )
    return hashlib.sha1(blob.encode()).hexdigest()[:12]


def _texts(node: Any) -> Iterator[str]:
    """Every text value in a tree of params."""
    if isinstance(node, str):
        yield node
    elif isinstance(node, dict):
        for v in node.values():
            yield from _texts(v)
    elif isinstance(node, list):
        for v in node:
            yield from _texts(v)


def trial_id(point: dict[str, Any], seed: int, resolved: str = "") -> str:
    """Stable id of a trial, independent of grid order.

    ``resolved`` is :func:`params_hash` of the trial's params: editing the
    experiment's base params (or a default of the kind) gives new ids, so a
    resumed sweep runs the trials again instead of keeping results of the
    old params under the new ones.
    """
    key: dict[str, Any] = {"point": point, "seed": seed}
    if resolved:
        key["params"] = resolved
    blob = json.dumps(key, sort_keys=True, default=str)
    return hashlib.sha1(blob.encode()).hexdigest()[:12]


def plan_trials(
    exp: ExperimentFile, kind: type[Experiment] | None = None, base_dir: Path | None = None
) -> list[TrialSpec]:
    """Every (grid point, seed) pair of the experiment; ids include the resolved params' hash when ``kind``
    is given (as :func:`run_sweep` does, with the experiment file's folder as ``base_dir``)."""
    out = []
    for point in grid_points(exp):
        resolved = params_hash(exp.experiment, params_for(kind, exp, point), base_dir) if kind is not None else ""
        out += [TrialSpec(trial_id=trial_id(point, seed, resolved), point=point, seed=seed) for seed in exp.seed_list()]
    return out


def current_rows(rows: list[dict[str, Any]], trials: list[TrialSpec]) -> list[dict[str, Any]]:
    """The log's rows of the planned trials, the last row of each (a retried trial's newest), in log order.

    Rows of other params (an edited experiment file) stay in the log but are
    not results of this sweep.
    """
    planned = {t.trial_id for t in trials}
    last: dict[str, int] = {}
    for i, r in enumerate(rows):
        if r.get("trial_id") in planned:
            last[r["trial_id"]] = i
    return [rows[i] for i in sorted(last.values())]
