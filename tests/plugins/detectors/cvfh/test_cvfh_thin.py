"""Thin parts told from the table by patch means (cvfh/thin.py)."""

from __future__ import annotations

import numpy as np

from asmteach.core.models import TablePlane
from asmteach.plugins.detectors.cvfh.thin import raised_mask


def _table_with_plate(thickness: float, sigma: float = 0.0015, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A 30 x 30 cm table sampled every 1.5 mm with Gaussian height noise, a 6 x 4 cm plate on it."""
    rng = np.random.default_rng(seed)
    g = np.arange(-0.15, 0.15, 0.0015)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    plate = (np.abs(x) < 0.03) & (np.abs(y) < 0.02)
    z = np.where(plate, thickness, 0.0) + rng.normal(0.0, sigma, x.shape)
    return np.column_stack([x, y, z]), plate


def test_a_3mm_plate_is_raised_though_every_point_is_below_the_removal_height() -> None:
    pts, plate = _table_with_plate(0.003)
    mask, threshold = raised_mask(pts, TablePlane(), low=0.007, high=0.5, cell=0.003, sigmas=6.0)
    assert 0.0 < threshold < 0.003
    assert mask[plate].mean() > 0.8  # the plate's edges blur into the table's patches
    # table points are raised only beside the plate's edges, within the 3 x 3 patches that overlap it
    stray = pts[mask & ~plate & (pts[:, 2] < 0.007)]  # higher ones are kept point by point, as before
    beyond = np.maximum(np.abs(stray[:, 0]) - 0.03, np.abs(stray[:, 1]) - 0.02)
    assert len(stray) < 0.05 * plate.sum() and beyond.max() < 0.0065


def test_a_bare_table_raises_nothing_and_points_above_the_removal_height_stay() -> None:
    pts, _ = _table_with_plate(0.0)
    pts = np.vstack([pts, [[0.0, 0.0, 0.02]]])
    mask, _ = raised_mask(pts, TablePlane(), low=0.007, high=0.5, cell=0.003, sigmas=6.0)
    assert mask[-1]
    assert mask[:-1].sum() < 5
