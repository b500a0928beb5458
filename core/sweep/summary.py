"""Sweep summaries: one flat record per trial, a table per grid point, CSV and markdown.

:func:`summarize` writes ``trials.csv``, ``summary.csv`` and ``summary.md``,
the kind's own outputs, and the generic figure when the kind draws none.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from asmteach.core.io import write_text
from asmteach.core.sweep.experiment import Experiment
from asmteach.core.sweep.plot import IMAGE_SUFFIXES, summary_plot


def flatten(row: dict[str, Any]) -> dict[str, Any]:
    """One flat record per trial: grid keys, seed, ok, error, the trial's wall time (``trial_seconds``, named
    apart from any metric of an experiment, such as the planning time ``seconds``) and the metrics."""
    flat: dict[str, Any] = {**row.get("point", {}), "seed": row.get("seed"), "ok": row.get("ok")}
    for k, v in (row.get("metrics") or {}).items():
        if isinstance(v, int | float | str | bool) or v is None:
            flat[k] = v
    flat["trial_seconds"] = row.get("seconds")
    flat["error"] = row.get("error") or ""
    return flat


def _num(v: Any) -> float | None:
    if isinstance(v, bool) or v is None:
        return float(v) if isinstance(v, bool) else None
    if isinstance(v, int | float) and math.isfinite(v):
        return float(v)
    return None


def group_table(rows: list[dict[str, Any]], keys: Iterable[str]) -> list[dict[str, Any]]:
    """Per grid point: trial count, the rate of trials that ran (``ok_rate``), the rate of each yes/no
    metric (``success_rate``) and the median / max of each numeric one."""
    import numpy as np

    keys = list(keys)
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for r in rows:
        f = flatten(r)
        groups.setdefault(tuple(json.dumps(f.get(k), default=str) for k in keys), []).append(f)
    table = []
    for gkey, members in groups.items():
        rec: dict[str, Any] = {k: json.loads(v) for k, v in zip(keys, gkey, strict=True)}
        rec["trials"] = len(members)
        rec["ok_rate"] = round(sum(bool(m["ok"]) for m in members) / len(members), 4)
        metric_names = [k for k in members[0] if k not in (*keys, "seed", "ok", "error")]
        for name in metric_names:
            flags = [m.get(name) for m in members if isinstance(m.get(name), bool)]
            if flags and len(flags) == sum(m.get(name) is not None for m in members):
                rec[f"{name}_rate"] = round(sum(flags) / len(flags), 4)  # a yes/no result: how often yes
                continue
            vals = [x for x in (_num(m.get(name)) for m in members) if x is not None]
            if vals:
                rec[f"{name}_median"] = round(float(np.median(vals)), 6)
                rec[f"{name}_max"] = round(float(np.max(vals)), 6)
        table.append(rec)
    return table


def to_csv(records: list[dict[str, Any]]) -> str:
    """Records as CSV text (union of keys, in first-seen order)."""
    cols: list[str] = []
    for r in records:
        cols += [k for k in r if k not in cols]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols)
    w.writeheader()
    for r in records:
        w.writerow({k: r.get(k, "") for k in cols})
    return buf.getvalue()


def to_markdown(records: list[dict[str, Any]], cols: list[str] | None = None) -> str:
    """Records as a GitHub markdown table."""
    if not records:
        return "_no trials_\n"
    cols = cols or list(dict.fromkeys(k for r in records for k in r))

    def cell(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:.4g}"
        return str(v).replace("|", "\\|")

    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(cell(r.get(c, "")) for c in cols) + " |" for r in records]
    return "\n".join(lines) + "\n"


def summarize(rows: list[dict[str, Any]], out: Path, kind: Experiment, *, title: str = "") -> list[Path]:
    """Generic summary (per-trial CSV, per-point table) plus the kind's own outputs.

    When the kind writes no figure, the generic :func:`summary_plot` is added.
    """
    keys = list(dict.fromkeys(k for r in rows for k in r.get("point", {})))
    flat = [flatten(r) for r in rows]
    table = group_table(rows, keys)
    paths = [
        write_text(out / "trials.csv", to_csv(flat)),
        write_text(out / "summary.csv", to_csv(table)),
    ]
    own = list(kind.summarize(rows, out) or [])
    plot = None
    if not any(Path(p).suffix.lower() in IMAGE_SUFFIXES for p in own):
        plot = summary_plot(rows, out, title=title or type(kind).__name__, metrics=kind.plot_metrics)
    n_ok = sum(bool(r.get("ok")) for r in rows)
    md = (
        f"# Sweep summary\n\n{len(rows)} trials, {n_ok} ran to the end ({len(rows) - n_ok} raised an error); "
        "a trial's own verdict is among its metrics.\n\n" + to_markdown(table)
    )
    if plot is not None:
        md += f"\n![summary]({plot.name})\n"
    failures = [r for r in rows if not r.get("ok")]
    if failures:
        md += "\n## Failed trials\n\n" + to_markdown(
            [
                {"trial": r["trial_id"], "seed": r["seed"], **r.get("point", {}), "error": r.get("error")}
                for r in failures[:50]
            ]
        )
    paths.append(write_text(out / "summary.md", md))
    return paths + own + ([plot] if plot is not None else [])
