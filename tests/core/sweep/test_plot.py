"""The generic sweep figure: which metrics, against which key, with which statistics."""

import numpy as np
import pytest

from asmteach.core.sweep import plot_axis_key, plot_columns, run_sweep, series_stats, summary_figure


def _row(point, seed, metrics=None, ok=True):
    return {
        "trial_id": f"{point}-{seed}",
        "point": point,
        "seed": seed,
        "ok": ok,
        "metrics": metrics or {},
        "error": None if ok else "boom",
        "seconds": 0.5,
    }


def test_series_stats_are_median_and_quartiles_per_x():
    x, med, q25, q75 = series_stats([2, 1, 1, 1, 2, 1], [10, 1, 2, 3, 20, 4])
    assert x.tolist() == [1.0, 2.0]
    assert np.allclose(med, [2.5, 15.0])
    assert np.allclose(q25, [1.75, 12.5]) and np.allclose(q75, [3.25, 17.5])


def test_axis_key_is_the_grid_key_with_most_values_and_columns_are_numeric_metrics():
    metrics = {"err": 1.5, "flag": True, "name": "x", "n": 3}
    rows = [_row({"a": a, "b": b}, 0, metrics) for a in (1, 2) for b in "pqr"]
    assert plot_axis_key(rows) == "b"
    assert plot_columns(rows) == ["err", "n"]  # bools and strings are not plotted
    assert plot_columns(rows, preferred=["n", "name", "absent"]) == ["n"]  # declared by the kind, if numeric
    assert plot_columns([_row({"a": 1}, 0, {"name": "x"})]) == ["trial_seconds"]
    assert plot_axis_key([_row({}, 0)]) is None
    many = [_row({"a": 1}, 0, {f"m{i}": i for i in range(9)})]
    assert len(plot_columns(many)) == 6


def test_numeric_key_gives_median_line_with_iqr_band_per_other_key():
    rows = [
        _row({"d": d, "mode": mode}, s, {"err": d * (2 if mode == "slow" else 1) + s})
        for d in (0.5, 1.0, 2.0)
        for mode in ("fast", "slow")
        for s in range(4)
    ]
    rows.append(_row({"d": 2.0, "mode": "fast"}, 9, ok=False))
    fig = summary_figure(rows, title="toy")
    rate_ax, err_ax = [ax for ax in fig.axes if ax.get_visible()]
    assert rate_ax.get_title() == "success rate" and err_ax.get_title() == "err"
    assert err_ax.get_xlabel() == "d"
    lines = {ln.get_label(): ln.get_xydata() for ln in err_ax.lines}
    assert set(lines) == {"mode=fast", "mode=slow"}
    assert np.allclose(lines["mode=fast"], [[0.5, 2.0], [1.0, 2.5], [2.0, 3.5]])  # median of d + {0,1,2,3}
    assert np.allclose(lines["mode=slow"][:, 1], [2.5, 3.5, 5.5])
    assert len(err_ax.collections) == 4  # an IQR band and a dot cloud per line
    band = err_ax.collections[0].get_paths()[0].vertices
    assert band[:, 1].min() == pytest.approx(0.5 + 0.75) and band[:, 1].max() == pytest.approx(2.0 + 2.25)
    rate = {ln.get_label(): ln.get_xydata() for ln in rate_ax.lines}
    assert np.allclose(rate["mode=fast"][:, 1], [1.0, 1.0, 0.8])


def test_categorical_key_gives_box_plots():
    rows = [_row({"detector": det}, s, {"err": s + (10 if det == "b" else 0)}) for det in ("a", "b") for s in range(5)]
    fig = summary_figure(rows)
    (ax,) = [a for a in fig.axes if a.get_visible()]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["a", "b"]
    medians = [
        ln.get_ydata()[0]
        for ln in ax.lines
        if ln.get_color() not in ("black", "k") and len(ln.get_ydata()) == 2 and ln.get_ydata()[0] == ln.get_ydata()[1]
    ]
    assert 2.0 in medians and 12.0 in medians


def test_nothing_to_draw_gives_no_figure():
    assert summary_figure([]) is None
    assert summary_figure([_row({"x": 1}, 0, {"label": "only text"})]) is not None  # falls back to seconds


@pytest.fixture
def square_file(toy_square_experiment):
    return toy_square_experiment


def test_sweep_writes_summary_png_when_the_kind_draws_none(square_file, tmp_path):
    out = tmp_path / "out"
    run_sweep(square_file, out, progress=False)
    png = out / "summary.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 5000
    assert "![summary](summary.png)" in (out / "summary.md").read_text()
    # no temporary files left behind (the lock file stays: removing it could let two sweeps lock two files)
    assert not [p for p in out.iterdir() if p.name.startswith(".") and p.name != ".sweep.lock"]


def test_no_generic_plot_when_the_kind_draws_its_own(tmp_path):
    from asmteach.core.models import StrictModel
    from asmteach.core.sweep import Experiment, summarize

    class Drawn(Experiment):
        Params = StrictModel

        def run_trial(self, params, seed, workdir):
            return {}

        def summarize(self, rows, out_dir):
            path = out_dir / "own.svg"
            path.write_text("<svg/>")
            return [path]

    rows = [_row({"x": x}, 0, {"err": x}) for x in (1, 2)]
    paths = summarize(rows, tmp_path, Drawn(tmp_path))
    assert tmp_path / "own.svg" in paths and not (tmp_path / "summary.png").exists()
    paths = summarize(rows, tmp_path / "b", Experiment.__new__(type("Plain", (Drawn,), {"summarize": lambda *a: []})))
    assert (tmp_path / "b" / "summary.png").exists()
