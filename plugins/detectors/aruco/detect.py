"""Marker detection in one frame with OpenCV's ``ArucoDetector`` and sub-pixel corner refinement."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Literal

import cv2
import numpy as np

from asmteach.plugins.detectors.aruco.markers import get_dictionary

__all__ = ["MarkerDetector", "refine_corners_edges"]

RefineMethod = Literal["edges", "subpix", "contour", "apriltag", "none"]

_REFINE = {
    "edges": cv2.aruco.CORNER_REFINE_SUBPIX,
    "subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
    "contour": cv2.aruco.CORNER_REFINE_CONTOUR,
    "apriltag": cv2.aruco.CORNER_REFINE_APRILTAG,
    "none": cv2.aruco.CORNER_REFINE_NONE,
}


class MarkerDetector:
    """Detects markers of several dictionaries; returns corners keyed by ``(dictionary, id)``.

    Corners are ``(4, 2) float64`` pixel coordinates in OpenCV's convention
    (pixel centres at integer coordinates), in OpenCV's corner order.
    """

    def __init__(
        self,
        dictionaries: Iterable[str],
        *,
        refine: RefineMethod = "edges",
        refine_window: int = 5,
        min_perimeter_rate: float = 0.01,
        edge_max_line_rms: float = 0.25,
        edge_min_inliers: float = 0.85,
        edge_noise_factor: float = 2.5,
    ) -> None:
        # The edge-fit acceptance limits (see :func:`refine_corners_edges`): ``edge_max_line_rms`` is a floor
        # (it suits clean renders); the limit used is raised to ``edge_noise_factor`` times the edge-point noise
        # measured on the marker itself, which a real JPEG needs (docs/results/real_sensor_data.md, section 2).
        self.edge_max_line_rms = float(edge_max_line_rms)
        self.edge_min_inliers = float(edge_min_inliers)
        self.edge_noise_factor = float(edge_noise_factor)
        self.refine = refine
        self.cells: dict[str, int] = {}
        self.detectors: dict[str, cv2.aruco.ArucoDetector] = {}
        for name in sorted(set(dictionaries)):
            params = cv2.aruco.DetectorParameters()
            params.cornerRefinementMethod = _REFINE[refine]
            params.cornerRefinementWinSize = int(refine_window)
            params.cornerRefinementMaxIterations = 60
            params.cornerRefinementMinAccuracy = 0.001
            # Small markers far from a 1280x720 camera are ~15 px across: allow them.
            params.minMarkerPerimeterRate = float(min_perimeter_rate)
            dictionary = get_dictionary(name)
            self.cells[name] = dictionary.markerSize + 2
            self.detectors[name] = cv2.aruco.ArucoDetector(dictionary, params)

    def detect(self, image: np.ndarray) -> dict[tuple[str, int], np.ndarray]:
        """Corners of every marker found in a BGR or grey ``uint8`` image."""
        grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
        found: dict[tuple[str, int], np.ndarray] = {}
        grey_f = grey.astype(np.float32) if self.refine == "edges" else None
        for name, det in self.detectors.items():
            corners, ids, _ = det.detectMarkers(grey)
            if ids is None:
                continue
            for c, i in zip(corners, ids.ravel(), strict=True):
                key = (name, int(i))
                if key in found:
                    # The same id twice in one frame cannot be told apart: drop both.
                    found[key] = np.full((4, 2), np.nan)
                    continue
                corners_px = np.asarray(c, dtype=np.float64).reshape(4, 2)
                if grey_f is not None:
                    refined = refine_corners_edges(
                        grey_f,
                        corners_px,
                        self.cells[name],
                        min_inliers=self.edge_min_inliers,
                        max_line_rms=self.edge_max_line_rms,
                        noise_factor=self.edge_noise_factor,
                    )
                    if refined is None:
                        continue  # partly occluded: its corners cannot be trusted
                    corners_px = refined
                found[key] = corners_px
        return {k: v for k, v in found.items() if np.all(np.isfinite(v))}


def _side_points(
    grey: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    outward: np.ndarray,
    half_width: float,
    plateau_tol: float = 0.15,
) -> tuple[np.ndarray, int]:
    """Sub-pixel edge points along the side ``a -> b`` of a dark square on a bright margin.

    Each point comes from an intensity profile across the edge: for an edge
    blurred by any symmetric kernel narrower than the window, the step's
    position is the window end minus the area under the normalised profile,
    which needs no edge model and averages the noise of every sample.
    Profiles that overshoot either plateau by more than ``plateau_tol`` of the
    contrast (plus three noise levels) are not clean steps and are dropped.
    """
    side = b - a
    length = float(np.linalg.norm(side))
    t = side / length
    n_along = max(6, int(0.7 * length))
    s = np.linspace(0.15, 0.85, n_along) * length
    step = 0.25
    d = np.arange(-half_width, half_width + 1e-9, step)
    pts = a[None, None, :] + s[:, None, None] * t + d[None, :, None] * outward  # (n_along, n_d, 2)
    prof = cv2.remap(
        grey,
        pts[..., 0].astype(np.float32),
        pts[..., 1].astype(np.float32),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    ).astype(np.float64)
    k = max(2, len(d) // 5)
    dark = prof[:, :k].mean(axis=1)
    bright = prof[:, -k:].mean(axis=1)
    contrast = bright - dark
    ok = contrast > 15.0
    norm = (prof - dark[:, None]) / np.where(ok, contrast, 1.0)[:, None]
    # A clean step rises once from one plateau to the other. When the window's bright end falls on something
    # darker than the margin (the mating part hiding the quiet zone, a shadow, a finger), the profile overshoots
    # its end level and the area estimate shifts the edge by a sizeable fraction of a pixel, with no trace in
    # the line fit (the occluder's edge is straight too). Such profiles are dropped; the tolerance grows with
    # the noise seen on the plateaus.
    noise = np.maximum(prof[:, :k].std(axis=1), prof[:, -k:].std(axis=1)) / np.where(ok, contrast, 1.0)
    tol = plateau_tol + 3.0 * noise
    ok &= (norm.max(axis=1) <= 1.0 + tol) & (norm.min(axis=1) >= -tol)
    area = np.trapezoid(np.clip(norm, -0.5, 1.5), d, axis=1)
    offset = d[-1] - area  # position of the step along the outward normal
    ok &= np.abs(offset) < 0.8 * half_width
    return (a[None, :] + s[:, None] * t + offset[:, None] * outward)[ok], n_along


def _fit_line(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, float, np.ndarray] | None:
    """Total-least-squares line ``(point, direction, inliers, rms, residuals)`` with 3-MAD outlier rejection.

    ``residuals`` are the signed distances (pixels) of the kept points from the line, in the points' order.
    """
    if len(points) < 4:
        return None
    r = np.zeros(len(points))
    signed = r
    for _ in range(2):
        c = points.mean(axis=0)
        _, _, vt = np.linalg.svd(points - c, full_matrices=False)
        direction, normal = vt[0], vt[1]
        signed = (points - c) @ normal
        r = np.abs(signed)
        keep = r <= max(3.0 * 1.4826 * float(np.median(r)), 0.05)
        if keep.all() or keep.sum() < 4:
            break
        points = points[keep]
    rms = float(np.sqrt(np.mean(r[keep] ** 2))) if keep.any() else np.inf
    return c, direction, len(points), rms, signed[keep]


def _point_noise(residuals: np.ndarray) -> float:
    """Scatter (pixels) of single edge points along a side, from differences of neighbouring points.

    Neighbouring profiles are ~1.4 px apart, so a smooth departure from the line (a bent or hidden edge) barely
    changes their difference while independent point noise enters it twice: ``std(diff) / sqrt(2)`` measures
    the noise alone, where the line RMS measures noise plus any misfit of the line.
    """
    if len(residuals) < 3:
        return 0.0
    return float(np.std(np.diff(residuals))) / np.sqrt(2.0)


def refine_corners_edges(
    grey: np.ndarray,
    corners: np.ndarray,
    cells: int,
    iterations: int = 2,
    *,
    min_inliers: float = 0.85,
    max_line_rms: float = 0.25,
    noise_factor: float = 2.5,
) -> np.ndarray | None:
    """Refine a marker's ``(4, 2)`` corners by fitting lines to its four outer edges.

    ``grey`` is a float32 image; ``cells`` is the marker's width in cells
    including the black border (the profile window stays inside the border
    cell and the white margin of one cell around it). Returns ``None`` when an
    edge is not a clean straight step: fewer than ``min_inliers`` of its
    profiles agree, or their line RMS exceeds the larger of ``max_line_rms``
    pixels and ``noise_factor`` times the marker's edge-point noise (the median
    over its sides of :func:`_point_noise`, pixels). The marker is then partly
    hidden (a finger over an edge) and its corners would be wrong while still
    fitting a single-marker PnP well.
    """
    out = np.asarray(corners, dtype=np.float64).copy()
    for _ in range(iterations):
        centre = out.mean(axis=0)
        side_len = np.linalg.norm(np.roll(out, -1, axis=0) - out, axis=1)
        half_width = float(np.clip(0.6 * side_len.min() / cells, 1.0, 4.0))
        fits = []
        for k in range(4):
            a, b = out[k], out[(k + 1) % 4]
            t = (b - a) / np.linalg.norm(b - a)
            outward = np.array([t[1], -t[0]])
            if np.dot(outward, 0.5 * (a + b) - centre) < 0:
                outward = -outward
            pts, n_total = _side_points(grey, a, b, outward, half_width)
            line = _fit_line(pts)
            if line is None or line[2] < min_inliers * n_total:
                return None
            fits.append(line)
        # A clean edge's line RMS is its points' noise: on a real 20 px marker in a JPEG (noise, 8 px blocks,
        # 2.5 px cells) 0.2-0.33 px, its point noise 0.15-0.23 px; on our renders 0.07 px and 0.04 px (medians).
        # A fixed limit set for one is too tight or too loose for the other, so the limit follows the noise measured
        # on this marker's own sides (the median, so one bent side barely moves it), never below
        # ``max_line_rms``.
        noise = float(np.median([_point_noise(f[4]) for f in fits]))
        if max(f[3] for f in fits) > max(max_line_rms, noise_factor * noise):
            return None
        lines = [f[:2] for f in fits]
        new = np.empty_like(out)
        for k in range(4):
            (p1, d1), (p2, d2) = lines[(k - 1) % 4], lines[k]
            A = np.column_stack([d1, -d2])
            if abs(np.linalg.det(A)) < 1e-6:
                return out
            s = np.linalg.solve(A, p2 - p1)
            new[k] = p1 + s[0] * d1
        if np.max(np.linalg.norm(new - out, axis=1)) > 3.0:
            return out  # a wild jump means the edges were not the marker's: keep OpenCV's corners
        out = new
    return out
