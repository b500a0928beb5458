"""The end of every run: the two clocks, the errors figure, report.json, the hooks' reports, report.html."""

from __future__ import annotations

from pathlib import Path

from asmteach.core.io import write_model
from asmteach.core.pipeline.stage import Run

__all__ = ["finish_run"]


def finish_run(run: Run) -> None:
    from asmteach.core.run_figures import metrics_figure

    # the computer's clock beside the robot's: wall seconds per stage (a stage run twice is summed)
    clock: dict[str, float] = {}
    for st in run.report.stages:
        clock[st.stage] = round(clock.get(st.stage, 0.0) + st.seconds, 3)
    clock["total"] = round(sum(st.seconds for st in run.report.stages), 3)
    run.report.computer_seconds = clock
    if run.report.metrics:
        path = metrics_figure(run.out / "errors.png", run.report)
        run.artefact("errors", path, "png")
    write_model(run.out / "report.json", run.report)
    extra = run.hook("asmteach_report_ready", report=run.report.model_dump(mode="json"), out_dir=run.out)
    for paths in extra or []:
        for p in paths or []:
            run.report.artefacts.setdefault(Path(p).name, str(p))
    try:
        from asmteach.core.report_html import write_report_html
    except ImportError:  # pragma: no cover - the HTML writer ships with the core
        write_report_html = None
    if write_report_html is not None:
        html = write_report_html(run.report, run.out)
        run.report.artefacts["html"] = str(Path(html).relative_to(run.out))
    write_model(run.out / "report.json", run.report)
