"""The camera centre a depth detection uses, and the clock that times its stages.

Shared by the depth detectors (``cvfh_icp``, ``fpfh_ransac``): both need the camera centre (world frame,
metres) to orient normals and cast the verification's rays, and both report per-stage times.
"""

from __future__ import annotations

import time

import numpy as np

from asmteach.core.errors import UserError

__all__ = ["NO_VIEWPOINT", "StageClock", "resolve_viewpoint"]

NO_VIEWPOINT = (
    "no camera position: give --viewpoint X Y Z (camera centre, world frame, metres), a PCD whose VIEWPOINT "
    "header holds it, a PLY written by asmteach's renderer ('comment viewpoint X Y Z'), or the detector's "
    "viewpoint setting in the config"
)
"""The :class:`UserError` message when no source gives the camera centre."""


def resolve_viewpoint(viewpoint: np.ndarray | None, setting: np.ndarray | None) -> np.ndarray:
    """The camera centre to use (world frame, metres): ``viewpoint`` when given, else the ``setting``.

    There is no built-in default: the viewpoint orients the descriptors and
    casts the verification's rays, and a guessed camera makes every right
    pose look wrong. Raises :class:`UserError` when neither is given, for
    anything but three finite numbers, or for a camera farther than 20 m from
    the world origin (a viewpoint in millimetres).
    """
    if viewpoint is None and setting is None:
        raise UserError(NO_VIEWPOINT)
    eye = np.asarray(setting if viewpoint is None else viewpoint, dtype=float)
    if eye.shape != (3,) or not np.all(np.isfinite(eye)):
        raise UserError(f"viewpoint must be 3 finite numbers (camera centre, world frame, metres), got {eye.tolist()}")
    if float(np.linalg.norm(eye)) > 20.0:
        raise UserError(
            f"viewpoint {eye.tolist()} is {np.linalg.norm(eye):.0f} m from the origin: give it in metres, not mm"
        )
    return eye


class StageClock:
    """Wall time per stage in milliseconds (``perf_counter``), plus the process CPU time of it all.

    ``cpu`` (process CPU time, all threads) is reported next to the wall-clock
    ``total`` because on a shared machine the wall clock also counts other
    people's work; with one thread the CPU time is what an idle core needs.
    """

    def __init__(self) -> None:
        self.ms: dict[str, float] = {}
        self._t = time.perf_counter()
        self._start = self._t
        self._cpu = time.process_time()

    def lap(self, stage: str) -> None:
        """Charge the time since the previous lap to ``stage``."""
        now = time.perf_counter()
        self.ms[stage] = self.ms.get(stage, 0.0) + 1000.0 * (now - self._t)
        self._t = now

    def done(self) -> dict[str, float]:
        """Stage times plus ``total`` (wall) and ``cpu``, rounded to 0.01 ms."""
        out = {k: round(v, 2) for k, v in self.ms.items()}
        out["total"] = round(1000.0 * (time.perf_counter() - self._start), 2)
        out["cpu"] = round(1000.0 * (time.process_time() - self._cpu), 2)
        return out
