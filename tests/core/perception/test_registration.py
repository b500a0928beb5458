"""icp_refine onto the model surface the camera sees (``viewpoint``) against the whole model: a cup turned over."""

from __future__ import annotations

import numpy as np
import trimesh

from asmteach.core import geometry
from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings, look_at
from asmteach.core.perception.registration import RefineSettings, icp_refine, model_cloud, visible_samples

EYE = np.array([1.05, 0.0, 0.75])
"""The cell Kinect's centre (world, metres), as in the pipeline's cell."""


def _cup() -> trimesh.Trimesh:
    """A 28 mm cup, 27 mm tall, turned over (open side down at z = 0): a 1.5 mm wall, a 2 mm top (metres)."""
    wall = trimesh.creation.annulus(r_min=0.0125, r_max=0.014, height=0.025, sections=48)
    wall.apply_translation([0.0, 0.0, 0.0125])
    top = trimesh.creation.cylinder(radius=0.014, height=0.002, sections=48)
    top.apply_translation([0.0, 0.0, 0.026])
    return trimesh.util.concatenate([wall, top])


def test_visible_samples_leave_out_the_inside() -> None:
    cup = _cup()
    model = model_cloud(cup, 2000)
    r = np.linalg.norm(model.points[:, :2], axis=1)
    inner = (r < 0.0130) & (model.points[:, 2] < 0.0249)  # the inside wall and the top's underside
    seen = visible_samples(model, np.array([0.3, 0.0, 0.3]))  # above and beside, part frame
    assert inner.sum() > 200
    assert not seen[inner].any()
    outer_facing = (r > 0.0135) & (model.points[:, 0] > 0.005) & (model.points[:, 2] < 0.024)
    assert seen[outer_facing].mean() > 0.95
    assert seen.sum() < 0.5 * len(seen)


def test_visible_target_drifts_less_on_a_cup_turned_over() -> None:
    """Noisy Kinect frames from 0.9 m, ICP started at the truth: onto the whole model the seen outside pairs with
    the inside wall 1.5 mm behind it and the pose slides off; onto the surface the camera sees it stays."""
    cup = _cup()
    model = model_cloud(cup, 4000)
    slab = trimesh.creation.box(extents=[0.8, 1.2, 0.02])
    T_slab = geometry.from_rotation(np.eye(3), [0.45, 0.0, -0.01])
    T_cam = look_at(EYE, [0.45, 0.0, 0.0])
    drift: dict[bool, list[float]] = {False: [], True: []}
    tilt: dict[bool, list[float]] = {False: [], True: []}
    for seed in range(4):
        rng = np.random.default_rng(seed)
        T = geometry.rot_z(rng.uniform(-np.pi, np.pi))
        T[:3, 3] = [0.45 + rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), 0.0]
        frame = DepthCamera(KinectSettings(), seed=seed).render([(slab, T_slab), (cup, T)], T_cam)
        seen = frame.points_world[frame.labels == 1]
        assert len(seen) > 150
        for visible in (False, True):
            T_fit = icp_refine(seen, model, T, RefineSettings(), viewpoint=EYE if visible else None)
            # the cup turns freely about its axis, and its origin lies on it: position and tilt are the error
            drift[visible].append(1000.0 * float(np.linalg.norm(T_fit[:3, 3] - T[:3, 3])))
            tilt[visible].append(float(np.degrees(np.arccos(np.clip(T_fit[:3, 2] @ T[:3, 2], -1.0, 1.0)))))
    assert np.median(drift[False]) > 0.8  # the drift the visible target is for (measured 1.0-1.9 mm)
    assert np.median(drift[True]) < 0.5 * np.median(drift[False])
    assert max(drift[True]) < 1.0
    assert max(tilt[True]) < 3.0
