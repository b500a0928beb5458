"""Marker detection in one frame with OpenCV's ``ArucoDetector`` and sub-pixel corner refinement."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Literal

import cv2
import numpy as np

from asmteach.plugins.detectors.aruco.markers import get_dictionary

__all__ = ["MarkerDetector"]

RefineMethod = Literal["subpix", "contour", "apriltag", "none"]

_REFINE = {
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
        refine: RefineMethod = "subpix",
        refine_window: int = 5,
        min_perimeter_rate: float = 0.01,
    ) -> None:
        self.detectors: dict[str, cv2.aruco.ArucoDetector] = {}
        for name in sorted(set(dictionaries)):
            params = cv2.aruco.DetectorParameters()
            params.cornerRefinementMethod = _REFINE[refine]
            params.cornerRefinementWinSize = int(refine_window)
            params.cornerRefinementMaxIterations = 60
            params.cornerRefinementMinAccuracy = 0.001
            # Small markers far from a 1280x720 camera are ~15 px across: allow them.
            params.minMarkerPerimeterRate = float(min_perimeter_rate)
            self.detectors[name] = cv2.aruco.ArucoDetector(get_dictionary(name), params)

    def detect(self, image: np.ndarray) -> dict[tuple[str, int], np.ndarray]:
        """Corners of every marker found in a BGR or grey ``uint8`` image."""
        grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
        found: dict[tuple[str, int], np.ndarray] = {}
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
                found[key] = np.asarray(c, dtype=np.float64).reshape(4, 2)
        return {k: v for k, v in found.items() if np.all(np.isfinite(v))}
