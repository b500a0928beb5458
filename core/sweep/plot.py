"""The generic sweep figure: each numeric metric against the grid key with most values (``summary.png``)."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from asmteach.core.io import atomic_path

if TYPE_CHECKING:
    from matplotlib.figure import Figure

IMAGE_SUFFIXES = frozenset({".png", ".svg", ".pdf", ".jpg", ".jpeg", ".gif"})
MAX_PLOT_METRICS = 6
MAX_PLOT_SERIES = 6


def _label(v: Any, width: int = 18) -> str:
    text = json.dumps(v, default=str) if isinstance(v, list | dict) else str(v)
    return text if len(text) <= width else text[: width - 1] + "…"


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def plot_columns(rows: list[dict[str, Any]], preferred: Iterable[str] = (), limit: int = MAX_PLOT_METRICS) -> list[str]:
    """Metrics worth a panel: numeric (not bool) in at least one successful trial.

    The ``preferred`` ones that are numeric come first, in their order; without
    them, the numeric metrics in first-seen order. Falls back to
    ``["trial_seconds"]`` (trial wall time) when no metric is numeric.
    """
    numeric = list(
        dict.fromkeys(k for r in rows if r.get("ok") for k, v in (r.get("metrics") or {}).items() if _is_number(v))
    )
    chosen = [k for k in dict.fromkeys(preferred) if k in numeric] or numeric
    return chosen[:limit] if chosen else ["trial_seconds"]


def plot_axis_key(rows: list[dict[str, Any]]) -> str | None:
    """The grid key with the most distinct values (file order breaks ties); None without a grid."""
    keys = list(dict.fromkeys(k for r in rows for k in r.get("point", {})))
    if not keys:
        return None
    counts = {k: len({json.dumps(r.get("point", {}).get(k), default=str) for r in rows}) for k in keys}
    return max(keys, key=lambda k: counts[k])


def series_stats(xs: list[float], ys: list[float]) -> tuple[Any, Any, Any, Any]:
    """Per distinct x (ascending): the median and the 25th and 75th percentiles of y.

    Returns ``(x, median, q25, q75)``, each a ``(k,)`` float array.
    """
    import numpy as np

    x = np.asarray(xs, dtype=float)
    y = np.asarray(ys, dtype=float)
    ux = np.unique(x)
    q = np.array([np.percentile(y[x == u], [50.0, 25.0, 75.0]) for u in ux]).reshape(-1, 3)
    return ux, q[:, 0], q[:, 1], q[:, 2]


def _metric_value(row: dict[str, Any], col: str) -> Any:
    return row.get("seconds") if col == "trial_seconds" else (row.get("metrics") or {}).get(col)


def summary_figure(rows: list[dict[str, Any]], *, title: str = "", metrics: Iterable[str] = ()) -> Figure | None:
    """The generic sweep figure, or None when there is nothing to draw.

    One panel per numeric metric (:func:`plot_columns`, ``metrics`` first;
    successful trials only) against the grid key with most values (:func:`plot_axis_key`). A
    numeric key gives the median line with its inter-quartile band and the
    trials as dots, one line per combination of the other grid keys (pooled
    when there are more than six); a categorical key (or none) gives box
    plots pooled over the other keys. If any trial failed, a first panel
    shows the success rate per key value.
    """
    import numpy as np
    from matplotlib.figure import Figure

    if not rows:
        return None
    x_key = plot_axis_key(rows)
    xs_all = [r.get("point", {}).get(x_key) for r in rows] if x_key else ["all"] * len(rows)
    numeric_x = x_key is not None and all(_is_number(v) for v in xs_all)
    other = [k for k in dict.fromkeys(k for r in rows for k in r.get("point", {})) if k != x_key]
    series_of = [", ".join(f"{k}={_label(r.get('point', {}).get(k))}" for k in other) for r in rows]
    pooled = len(set(series_of)) > MAX_PLOT_SERIES
    if pooled or not numeric_x:
        series_of = [""] * len(rows)
    cols = plot_columns(rows, metrics)
    if not any(_is_number(_metric_value(r, c)) for r in rows if r.get("ok") for c in cols):
        cols = []
    any_failed = not all(r.get("ok") for r in rows)
    panels = (["success rate"] if any_failed else []) + cols
    if not panels:
        return None

    ncols = min(3, len(panels))
    nrows = math.ceil(len(panels) / ncols)
    fig = Figure(figsize=(4.4 * ncols, 3.4 * nrows), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    categories = list(dict.fromkeys(json.dumps(v, default=str) for v in xs_all))
    for ax, panel in zip(axes, panels, strict=False):
        is_rate = panel == "success rate"
        pts = [
            (x, s, 1.0 if r.get("ok") else 0.0) if is_rate else (x, s, _metric_value(r, panel))
            for x, s, r in zip(xs_all, series_of, rows, strict=True)
            if is_rate or (r.get("ok") and _is_number(_metric_value(r, panel)))
        ]
        if numeric_x:
            for name in dict.fromkeys(s for _, s, _ in pts):
                px = [float(x) for x, s, _ in pts if s == name]
                py = [float(y) for _, s, y in pts if s == name]
                ux, med, q25, q75 = series_stats(px, py)
                if is_rate:
                    med = np.array([np.mean([y for x, y in zip(px, py, strict=True) if x == u]) for u in ux])
                (line,) = ax.plot(ux, med, marker="o", label=name or None)
                if not is_rate:
                    ax.fill_between(ux, q25, q75, color=line.get_color(), alpha=0.25, linewidth=0)
                    ax.scatter(px, py, s=8, color=line.get_color(), alpha=0.35)
            if any(s for _, s, _ in pts):
                ax.legend(fontsize="x-small")
        else:
            data = [[float(y) for x, _, y in pts if json.dumps(x, default=str) == c] for c in categories]
            labels = [_label(json.loads(c)) for c in categories]
            if is_rate:
                ax.bar(range(1, len(data) + 1), [sum(d) / len(d) if d else 0.0 for d in data])
                ax.set_xticks(range(1, len(data) + 1), labels)
            else:
                keep = [i for i, d in enumerate(data) if d]
                ax.boxplot([data[i] for i in keep], positions=[i + 1 for i in keep], widths=0.6)
                ax.set_xticks(range(1, len(data) + 1), labels)
            if len(categories) > 4:
                ax.tick_params(axis="x", labelrotation=30)
        if is_rate:
            ax.set_ylim(-0.05, 1.05)
        ax.set_title(panel + (" (s)" if panel.endswith("seconds") else ""), fontsize="medium")
        ax.set_xlabel(x_key or "")
        ax.grid(alpha=0.3)
    for ax in axes[len(panels) :]:
        ax.set_visible(False)
    n_ok = sum(bool(r.get("ok")) for r in rows)
    note = f"; pooled over {', '.join(other)}" if other and (pooled or not numeric_x) else ""
    fig.suptitle(f"{title}: {len(rows)} trials, {n_ok} ok{note}" if title else f"{len(rows)} trials{note}")
    return fig


def summary_plot(rows: list[dict[str, Any]], out: Path, *, title: str = "", metrics: Iterable[str] = ()) -> Path | None:
    """Write :func:`summary_figure` to ``out/summary.png`` atomically; None when there is nothing to draw."""
    fig = summary_figure(rows, title=title, metrics=metrics)
    if fig is None:
        return None
    path = Path(out) / "summary.png"
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    return path
