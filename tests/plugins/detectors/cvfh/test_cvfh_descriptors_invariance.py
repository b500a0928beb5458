"""Invariances: CVFH under a rigid motion of cloud and viewpoint; CRH under a roll about the view axis."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from asmteach.plugins.detectors.cvfh.descriptors import compute_crh, compute_cvfh, crh_roll_candidates
from asmteach.plugins.detectors.cvfh.descriptors.crh import roll_histogram


def _circ_deg(a: float, b: float) -> float:
    """Absolute circular difference of two angles, degrees."""
    return abs((np.degrees(a - b) + 180.0) % 360.0 - 180.0)


@pytest.mark.parametrize("seed", [0, 1])
def test_cvfh_is_invariant_to_a_rigid_motion_of_cloud_and_viewpoint(pcl_view: Any, seed: int) -> None:
    rng = np.random.default_rng(seed)
    rot = Rotation.random(random_state=rng)
    t = rng.uniform(-1.0, 1.0, size=3)
    before = compute_cvfh(pcl_view.points, pcl_view.normals, pcl_view.curvatures)
    after = compute_cvfh(rot.apply(pcl_view.points) + t, rot.apply(pcl_view.normals), pcl_view.curvatures, viewpoint=t)
    assert len(after) == len(before)
    for a, b in zip(before, after, strict=True):
        np.testing.assert_array_equal(a.indices, b.indices)
        np.testing.assert_allclose(rot.apply(a.centroid) + t, b.centroid, atol=1e-12)
        np.testing.assert_allclose(rot.apply(a.normal), b.normal, atol=1e-9)
        # Bins may only differ where a float64 feature sits exactly on a bin edge: at most one point per block.
        assert np.abs(a.hist - b.hist).sum() <= 2.0


def test_cvfh_moves_with_the_cloud_when_the_viewpoint_stays(pcl_view: Any) -> None:
    """Control for the test above: turning the cloud about its own centroid, camera fixed, changes the histograms."""
    rot = Rotation.from_euler("x", 40, degrees=True)
    c = pcl_view.points.mean(axis=0)
    before = compute_cvfh(pcl_view.points, pcl_view.normals, pcl_view.curvatures)
    after = compute_cvfh(rot.apply(pcl_view.points - c) + c, rot.apply(pcl_view.normals), pcl_view.curvatures)
    assert np.abs(before[0].hist[180:] - after[0].hist[180:]).sum() > 10


@pytest.mark.parametrize("k", [1, 7, -30, 45])
def test_roll_by_whole_bins_shifts_crh_cyclically(pcl_view: Any, k: int) -> None:
    rot = Rotation.from_euler("z", 4 * k, degrees=True)
    centroid = pcl_view.points.mean(axis=0)
    h_a = roll_histogram(pcl_view.normals, centroid)
    h_b = roll_histogram(rot.apply(pcl_view.normals), rot.apply(centroid))
    # Noise-free renders repeat normals exactly, so a normal on a bin edge can move a whole group: allow 2 %.
    assert np.abs(np.roll(h_a, k) - h_b).sum() < 0.02
    # In PCL's packed spectrum the shift is a phase ramp exp(-2 pi i j k / 90).
    crh_a = compute_crh(pcl_view.points, pcl_view.normals, centroid)
    crh_b = compute_crh(rot.apply(pcl_view.points), rot.apply(pcl_view.normals), rot.apply(centroid))
    j = np.arange(1, 45)
    spec_a = crh_a[1:89:2] + 1j * crh_a[2:89:2]
    spec_b = crh_b[1:89:2] + 1j * crh_b[2:89:2]
    np.testing.assert_allclose(spec_a * np.exp(-2j * np.pi * j * k / 90), spec_b, atol=0.02)


@pytest.mark.parametrize("roll_deg", [5.0, 37.0, -123.0, 171.0, 90.0])
def test_roll_candidates_recover_a_known_roll(pcl_view: Any, roll_deg: float) -> None:
    rot = Rotation.from_euler("z", roll_deg, degrees=True)
    centroid = pcl_view.points.mean(axis=0)
    crh_a = compute_crh(pcl_view.points, pcl_view.normals, centroid)
    crh_b = compute_crh(rot.apply(pcl_view.points), rot.apply(pcl_view.normals), rot.apply(centroid))
    rolls = crh_roll_candidates(crh_a, crh_b)
    truth = np.radians(roll_deg)
    assert _circ_deg(rolls[0], truth) <= 4.0  # within one 4-degree histogram bin
    # Unlike PCL, the half-turn ambiguity is always among the candidates.
    assert min(_circ_deg(r, truth + np.pi) for r in rolls) <= 4.0
    assert all(-np.pi < r <= np.pi for r in rolls)


@pytest.mark.parametrize("roll_deg", [-64.0, 29.0])
def test_roll_about_a_given_view_axis_is_recovered(view_loader: Any, roll_deg: float) -> None:
    """Views expressed in a frame whose view axis is not z: a roll about that axis is recovered."""
    view = view_loader("07")
    frame = Rotation.from_euler("xyz", [30, -50, 10], degrees=True)
    roll = Rotation.from_euler("z", roll_deg, degrees=True)
    axis = frame.apply([0.0, 0.0, 1.0])
    c = view.points.mean(axis=0)
    crh_a = compute_crh(frame.apply(view.points), frame.apply(view.normals), frame.apply(c), view_axis=axis)
    moved = frame * roll
    crh_b = compute_crh(moved.apply(view.points), moved.apply(view.normals), moved.apply(c), view_axis=axis)
    assert _circ_deg(crh_roll_candidates(crh_a, crh_b)[0], np.radians(roll_deg)) <= 4.0
