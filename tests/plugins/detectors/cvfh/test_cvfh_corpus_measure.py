"""The part-corpus detection measure: seeded scenes of one part, scored symmetry-aware."""

from __future__ import annotations

from pathlib import Path

from asmteach.core.parts import build_part, load_structure
from asmteach.plugins.detectors.cvfh.corpus_measure import asmteach_measure_part

STRUCTURE = Path(__file__).resolve().parents[4] / "configs/parts/set1/peg_in_hole.yaml"


def test_a_plain_part_is_found_in_its_scenes(tmp_path: Path) -> None:
    part = build_part(load_structure(STRUCTURE).part_a)
    out = asmteach_measure_part(part=part, stage="detection", seed=0, workdir=tmp_path, options={"scenes": 2})
    assert out is not None and out["scenes"] == 2
    assert out["success"] == 2 and out["wrong_found"] == 0
    assert out["max_pos_mm_found"] <= 5.0 and out["max_rot_deg_found"] <= 5.0
    assert out["frames"] == 4 and out["close_looks"] == 2  # as a run senses and looks by default
    assert out["view_success"] <= out["success"]  # the looks only ever add to what the Kinect's view found
    assert asmteach_measure_part(part=part, stage="grasps", seed=0, workdir=tmp_path, options={}) is None


def test_the_kinect_views_stack_frames_as_a_run_senses_the_first_frame_unchanged() -> None:
    """``frames`` Kinect frames, new noise in each, go into the detector's cloud (a run's execution.depth_frames);
    the first is the frame a single-frame scene has."""
    import numpy as np

    from asmteach.core.models import Detection
    from asmteach.plugins.detectors.cvfh.corpus_measure import DEPTH_FRAMES, run_part

    class Recorder:
        def __init__(self) -> None:
            self.clouds: list[np.ndarray] = []

        def prepare(self, part: object) -> None:
            pass

        def detect(self, cloud: np.ndarray, part: object, viewpoint: object = None) -> Detection:
            self.clouds.append(np.asarray(cloud))
            return Detection(part="box", found=False, reason="recorded")

    part = build_part(load_structure(STRUCTURE).part_a)
    got = {}
    for frames in (1, 3):
        rec = Recorder()
        run_part("box", part.mesh, part, rec, 1, 0, frames=frames)  # type: ignore[arg-type]
        got[frames] = rec.clouds[0]
    one, three = got[1], got[3]
    assert 2.9 * len(one) < len(three) < 3.1 * len(one)  # each frame drops its own pixels
    assert np.array_equal(three[: len(one)], one, equal_nan=True)
    assert not np.allclose(three[len(one) : 2 * len(one)], one, equal_nan=True)  # new noise
    assert DEPTH_FRAMES == 4
