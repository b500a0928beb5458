"""A run report a person wants to look at: one self-contained ``report.html`` and a console summary.

:func:`write_report_html` turns a :class:`~asmteach.core.models.RunReport`
into a single HTML file with inline CSS and every figure the run wrote (the
PNG/GIF/SVG/JPEG files named in ``report.artefacts``) embedded as base64
``data:`` URIs, so it can be mailed, archived or printed on its own: it
names no external URL. :func:`format_summary` gives the same facts in at
most 25 plain-text lines for the console.

Units on the page: positions in millimetres, angles in degrees (poses as
``x, y, z`` mm and fixed-axis ``roll, pitch, yaw`` deg); everything in the
report itself is metres and radians.

Detection errors are computed when a detection's ``details`` holds the
simulator's true pose under one of :data:`TRUE_POSE_KEYS` (a 4x4
``T_world_part``). They are plain errors of the estimate against that pose,
not reduced over the part's symmetries.

The package: :mod:`.facts` (what both show: values, poses, errors against the
true pose, the robot's clock), :mod:`.page` (the HTML page) and
:mod:`.console` (the summary).
"""

from __future__ import annotations

from asmteach.core.report_html.console import format_summary
from asmteach.core.report_html.facts import TRUE_POSE_KEYS
from asmteach.core.report_html.page import IMAGE_TYPES, render_report_html, write_report_html

__all__ = ["IMAGE_TYPES", "TRUE_POSE_KEYS", "format_summary", "render_report_html", "write_report_html"]
