"""The example third-party hook package, installed for real with pip (offline) and used through its entry point.

examples/asmteach-csv-reporter is copied to tmp (so the build leaves no
files in the repository), built and installed with the project's pip into a
temporary target folder without network, and then exercised in fresh
interpreters with that folder on PYTHONPATH: exactly how a user's
``pip install`` makes asmteach find a plugin.
"""

import csv
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "asmteach-csv-reporter"


@pytest.fixture(scope="module")
def installed_site(tmp_path_factory):
    """Folder into which pip installed the example distribution."""
    tmp = tmp_path_factory.mktemp("csv_reporter")
    src = tmp / "src"
    shutil.copytree(EXAMPLE, src, ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
    site = tmp / "site"
    env = {**os.environ, "PIP_NO_INDEX": "1", "PIP_DISABLE_PIP_VERSION_CHECK": "1"}  # prove: no network needed
    cmd = [
        sys.executable,
        "-m",
        "pip",
        "install",
        "--quiet",
        "--no-deps",
        "--no-build-isolation",
        "--target",
        str(site),
        str(src),
    ]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=240)
    assert done.returncode == 0, done.stderr[-3000:]
    return site


def _run(args, site, **kw):
    env = {**os.environ, "COLUMNS": "200"}
    env.pop("PYTHONPATH", None)
    if site is not None:
        env["PYTHONPATH"] = str(site)
    return subprocess.run([sys.executable, *args], env=env, capture_output=True, text=True, timeout=120, **kw)


@pytest.mark.slow
def test_pip_installed_a_real_distribution_with_the_entry_point(installed_site):
    (info,) = installed_site.glob("asmteach_csv_reporter-0.1.0.dist-info")
    assert "csv_reporter = asmteach_csv_reporter.reporter:plugin" in (info / "entry_points.txt").read_text()
    assert (installed_site / "asmteach_csv_reporter" / "reporter.py").is_file()


@pytest.mark.slow
def test_asmteach_plugins_lists_it_only_when_installed(installed_site):
    done = _run(["-m", "asmteach.core.cli", "plugins"], installed_site)
    assert done.returncode == 0, done.stderr
    (line,) = [ln for ln in done.stdout.splitlines() if "csv_reporter" in ln]
    assert "asmteach.hooks" in line and "asmteach-csv-reporter" in line and "0.1.0" in line
    assert " ok" in line and "error" not in line
    without = _run(["-m", "asmteach.core.cli", "plugins"], None)
    assert without.returncode == 0 and "csv_reporter" not in without.stdout


SCRIPT = textwrap.dedent(
    """
    import json, sys
    from pathlib import Path
    from asmteach.core.hooks import make_plugin_manager
    from asmteach.core.models import RunReport, StageOutcome

    pm = make_plugin_manager(progress=False)
    assert pm.get_plugin("csv_reporter") is not None, pm.list_name_plugin()
    # Observed live: teach (the report's own time wins) and plan (absent from the report).
    pm.hook.asmteach_stage_finished(stage="teach", ok=True, seconds=9.9, summary={})
    pm.hook.asmteach_stage_finished(stage="plan", ok=True, seconds=2.0, summary={})
    report = RunReport(
        config={"name": "demo, \\"quoted\\""},
        seed=7,
        success=False,
        failed_stage="detect",
        reason='part_a: no view matched, fitness 0.12 < 0.3',
        stages=[
            StageOutcome(stage="teach", ok=True, seconds=1.25),
            StageOutcome(stage="detect", ok=False, seconds=0.5, reason="part_a: no view matched"),
        ],
        metrics={"err_mm": 0.42, "err_deg": 0.17},
    )
    results = pm.hook.asmteach_report_ready(report=report.model_dump(mode="json"), out_dir=Path(sys.argv[1]))
    print(json.dumps([[str(p) for p in r] for r in results if r]))
    """
)


@pytest.mark.slow
def test_report_ready_writes_the_csv_row_through_the_plugin_manager(installed_site, tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    done = _run(["-c", SCRIPT, str(out)], installed_site)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == [[str(out / "run_summary.csv")]]
    with open(out / "run_summary.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 1
    assert rows[0] == {
        "config": 'demo, "quoted"',
        "seed": "7",
        "success": "False",
        "failed_stage": "detect",
        "reason": "part_a: no view matched, fitness 0.12 < 0.3",
        "stage_teach_s": "1.25",
        "stage_detect_s": "0.5",
        "stage_plan_s": "2.0",
        "metric_err_mm": "0.42",
        "metric_err_deg": "0.17",
    }
    assert [p.name for p in out.iterdir()] == ["run_summary.csv"]  # written atomically: no temporary left
