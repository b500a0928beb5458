"""asmteach-csv-reporter: an example third-party asmteach hook plugin.

It writes ``run_summary.csv`` (one row per run: outcome, stage times,
metrics) next to every ``report.json``. See :mod:`asmteach_csv_reporter.reporter`.
"""

__version__ = "0.1.0"
