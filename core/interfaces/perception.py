"""The perception roles: :class:`Teacher` (demonstration -> task), :class:`Detector` (cloud -> rough pose),
:class:`Corrector` (rough pose -> physically consistent pose).

Frames: ``T_world_*`` poses are in the world frame (z up, metres); parts are described in their part frame.
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from asmteach.core.interfaces.part_model import PartModel
from asmteach.core.interfaces.plugin import Plugin
from asmteach.core.models import AssemblyTask, CameraIntrinsics, Correction, Detection, StrictModel, TablePlane

__all__ = ["Corrector", "Detector", "Teacher"]


# ---------------------------------------------------------------- teaching
class Teacher(Plugin):
    """Learns an :class:`AssemblyTask` from RGB frames of a human demonstration."""

    DemoSettings: ClassVar[type[StrictModel] | None] = None
    """The model of the run config's ``demo`` section, for a teacher that renders demonstrations
    (:meth:`demonstrate`); ``None``: the teacher takes no ``demo`` section (one given is an error)."""

    @abc.abstractmethod
    def teach(
        self,
        frames: Sequence[np.ndarray],
        camera: CameraIntrinsics,
        task: AssemblyTask,
    ) -> AssemblyTask:
        """Estimate ``T_A_B`` and ``v_a`` from ``frames``.

        Parameters
        ----------
        frames : sequence of ``(h, w, 3) uint8`` BGR images, in time order.
        camera : intrinsics of the camera that took them.
        task : the parts (with their markers); its ``T_A_B``/``v_a`` are a prior
            at most and must not be copied into the result.

        Returns the task with the learned ``T_A_B``, ``v_a`` and ``evidence``.
        Raises :class:`~asmteach.core.errors.UserError` when the frames cannot
        support an estimate (no marker of a part seen, too few frames).
        """

    def demonstrate(
        self,
        task: AssemblyTask,
        demo: dict[str, Any],
        camera_file: Path | None = None,
        out_dir: Path | None = None,
    ) -> tuple[list[np.ndarray], CameraIntrinsics]:
        """Synthetic demonstration frames of ``task`` (its true ``T_A_B``/``v_a``) for simulated runs.

        ``demo`` holds the renderer's settings (the config's ``demo`` section);
        ``camera_file`` optional intrinsics; when ``out_dir`` is given the
        frames and their ground truth are written there too. Optional: a
        teacher that cannot render raises ``NotImplementedError``.
        """
        raise NotImplementedError(f"{type(self).__name__} cannot render demonstrations")


# ---------------------------------------------------------------- detection
class Detector(Plugin):
    """Finds the pose of one known part in a depth point cloud."""

    takes_cloud_models: ClassVar[bool] = False
    """Whether the detector works from a part given as a scan (``PartModel.points``), not only a mesh."""

    def prepare(self, part: PartModel) -> None:
        """Build or load per-part data (view databases); called once per part."""

    @abc.abstractmethod
    def detect(
        self,
        cloud: np.ndarray,
        part: PartModel,
        table: TablePlane | None = None,
        viewpoint: np.ndarray | None = None,
    ) -> Detection:
        """Detect ``part`` in ``cloud``.

        Parameters
        ----------
        cloud : ``(n, 3) float`` points in the world frame (metres, z up),
            the table below the part. NaN rows are ignored.
        part : the part to find.
        table : the table plane when known; otherwise the detector fits it.
        viewpoint : ``(3,)`` camera centre in the world frame (metres) when
            known (view-dependent descriptors need it); otherwise the
            detector's own setting.

        Returns a :class:`Detection` with ``rough`` set, or ``found=False`` and
        a ``reason``; never a wrong pose reported as found when verification fails.
        """


class Corrector(Plugin):
    """Turns a rough pose into one consistent with physical constraints."""

    @abc.abstractmethod
    def correct(
        self,
        T_world_part: np.ndarray,
        part: PartModel,
        table: TablePlane,
        cloud: np.ndarray | None = None,
        viewpoint: np.ndarray | None = None,
    ) -> Correction:
        """Correct a rough ``(4, 4)`` pose of ``part`` resting on ``table``.

        ``cloud`` (world frame) is the observed segment of the part, if the
        corrector refines against it; ``viewpoint`` the ``(3,)`` camera centre
        in the world frame (metres) when known.
        """
