"""report.html: self-contained, well-formed, escaped, with the right numbers; the console summary fits a screen."""

import base64
import math
import re
from html.parser import HTMLParser

import numpy as np
import pytest

from asmteach.core import geometry
from asmteach.core.failures import FailureCause
from asmteach.core.models import (
    AssemblyTask,
    Detection,
    PartSpec,
    Primitive,
    RunReport,
    SolidSpec,
    StageOutcome,
    TeachingEvidence,
)
from asmteach.core.report_html import format_summary, write_report_html

VOID = {"meta", "img", "br", "hr", "link", "input"}


class Checker(HTMLParser):
    """Collects images and text and checks that every element is closed in order."""

    def __init__(self):
        super().__init__()
        self.stack, self.errors, self.imgs, self.text, self.tags = [], [], [], [], []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        if tag == "img":
            self.imgs.append(dict(attrs))
        if tag not in VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes {self.stack[-1:] or 'nothing'}")
        else:
            self.stack.pop()

    def handle_data(self, data):
        self.text.append(data)


def _box(name):
    return PartSpec(name=name, solid=SolidSpec(add=[Primitive(shape="box", size=[0.05, 0.04, 0.02])]))


def _report(tmp_path, **overrides):
    T_true = geometry.from_xyz_rpy([0.40, -0.10, 0.01], np.radians([0.0, 0.0, 30.0]))
    # corrected: 1 mm off in x and 2 deg about z; rough: 3 mm off in y
    shift_x = geometry.from_xyz_rpy([0.001, 0, 0], [0, 0, 0])
    corrected = geometry.compose(shift_x, T_true, geometry.rot_z(math.radians(2)))
    rough = geometry.compose(geometry.from_xyz_rpy([0, 0.003, 0], [0, 0, 0]), T_true)
    fields = dict(
        config={"name": '<script>alert("x")</script> & co'},
        seed=3,
        success=False,
        failed_stage="plan",
        reason="IK failed at keyframe 'pre-insert' <arm=left>",
        failure_cause=FailureCause.MOTION,
        stages=[
            StageOutcome(stage="teach", ok=True, seconds=1.234, details={"frames": 30}),
            StageOutcome(stage="plan", ok=False, seconds=0.5, reason="no IK <left>", details={"keyframe": "pre"}),
        ],
        task=AssemblyTask(
            name="peg_in_hole",
            part_a=_box("a"),
            part_b=_box("b"),
            T_A_B=geometry.from_xyz_rpy([0.01, 0.02, 0.03], np.radians([10.0, 0.0, 90.0])),
            v_a=[0.0, 0.0, -2.0],
            evidence=TeachingEvidence(
                frames_total=30,
                frames_used=[0, 1, 2],
                residuals_px=[0.2, 0.4, 0.3],
                spread_mm=0.12,
                insertion_source="demonstration",
                notes=["note <b>"],
            ),
        ),
        detections=[
            Detection(
                part="a",
                found=True,
                rough=rough,
                corrected=corrected,
                fitness=0.91,
                inlier_rmse=0.0012,
                details={"T_world_part_true": T_true.tolist()},
            ),
            Detection(part="b", found=False, reason="no view matched <fitness 0.1>"),
        ],
        plan_stats={"grasps_tried": 12, "regrasps": 1, "path": ["p0", "p3"]},
        metrics={"err_b_in_a_mm": 0.731, "err_b_in_a_deg": 0.25},
        artefacts={},
    )
    fields.update(overrides)
    return RunReport(**fields)


@pytest.fixture
def png(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(2, 1.5))
    fig.subplots().plot([0, 1, 2], [0, 1, 4])
    path = tmp_path / "figs" / "errors.png"
    path.parent.mkdir()
    fig.savefig(path)
    return path


def test_report_html_is_self_contained_well_formed_and_escaped(tmp_path, png):
    (tmp_path / "report.json").write_text("{}")
    report = _report(
        tmp_path,
        artefacts={
            "error plot <1>": "figs/errors.png",
            "report data": "report.json",
            "escaped": "../outside.png",
            "animation": "missing.gif",
        },
    )
    path = write_report_html(report, tmp_path)
    assert path == tmp_path / "report.html"
    text = path.read_text(encoding="utf-8")
    parser = Checker()
    parser.feed(text)
    parser.close()
    assert parser.errors == [] and parser.stack == []
    assert {"html", "head", "style", "body", "table", "figure", "figcaption"} <= set(parser.tags)

    # the one existing image is embedded byte for byte, nothing is fetched from anywhere
    (img,) = parser.imgs
    assert img["src"].startswith("data:image/png;base64,")
    assert base64.b64decode(img["src"].split(",", 1)[1]) == png.read_bytes()
    assert img["alt"] == "error plot <1>"
    assert not re.search(r"https?://", text) and "<link" not in text and "<script" not in text
    assert 'src="figs' not in text

    # user strings are escaped, not interpreted
    assert "&lt;script&gt;alert(&quot;x&quot;)&lt;/script&gt; &amp; co" in text
    assert "&lt;arm=left&gt;" in text and "note &lt;b&gt;" in text
    words = " ".join(parser.text)
    assert "FAILED at plan" in words and "IK failed at keyframe 'pre-insert' <arm=left>" in words
    assert "Cause: motion · Reason: IK failed" in re.sub(r"\s+", " ", words)  # the cause beside the reason

    # the numbers: taught pose in mm / deg, unit v_a, detection errors against the true pose
    assert "+10.00, +20.00, +30.00" in words and "+10.00, +0.00, +90.00" in words
    assert "+0.0000, +0.0000, -1.0000" in words
    assert "1.00 (+1.00, +0.00, +0.00) 2.00" in words  # corrected: 1 mm in x, 2 deg
    assert "3.00 (+0.00, +3.00, +0.00) 0.00" in words  # rough: 3 mm in y, no rotation
    assert "no view matched <fitness 0.1>" in words
    assert "grasps_tried" in words and "err_b_in_a_mm" in words and "0.731" in words
    assert "outside the output folder" in words and "missing" in words
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # atomic write left no temporary


def test_report_without_task_detections_or_figures_still_renders(tmp_path):
    report = RunReport(config={}, seed=0, success=True)
    text = write_report_html(report, tmp_path).read_text()
    parser = Checker()
    parser.feed(text)
    assert parser.errors == [] and "SUCCESS" in text and "no task was taught" in text and "no figures" in text


def test_format_summary_fits_one_screen(tmp_path):
    text = format_summary(_report(tmp_path, artefacts={"html": "report.html"}))
    lines = text.splitlines()
    assert lines[0].endswith("(seed 3): FAILED at plan") and lines[1].startswith("  reason (motion): IK failed at")
    assert any("a: [" in ln and "error 1.00 mm / 2.00 deg" in ln for ln in lines)
    assert any("b: not found (no view matched" in ln for ln in lines)
    assert "files: report.html" in lines
    big = _report(
        tmp_path,
        reason="line one\nline two",
        stages=[StageOutcome(stage=f"s{i}", ok=True, seconds=i) for i in range(12)],
        metrics={f"m{i}": float(i) for i in range(30)},
        detections=[Detection(part=f"p{i}", found=False, reason="x" * 300) for i in range(6)],
    )
    lines = format_summary(big).splitlines()
    assert len(lines) <= 25 and max(map(len, lines)) <= 100
    assert "line one line two" in lines[1]
    old = format_summary(_report(tmp_path, failure_cause=None)).splitlines()  # a report.json from before causes
    assert old[1].startswith("  reason: IK failed at")
