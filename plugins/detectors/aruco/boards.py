"""Marker specs from a printed ChArUco board layout, and a board split into two pseudo-parts.

A ChArUco board printed on paper is a rigid set of markers whose poses are
known from the layout (OpenCV's ``CharucoBoard``: marker ids ``0 .. N-1`` in
the white squares, row by row). Splitting its markers into two groups and
calling them parts A and B gives a real photo with a known ``T_A_B``: the
check that the teacher's multi-marker pose works on a sensor's image, not only
on our renderer's (:mod:`benchmarks.real_markers`).

Frames: the board frame is OpenCV's (origin at the board's top-left outer
corner, x along the columns, y down the rows, z into the paper); a marker frame
is :class:`~asmteach.core.models.MarkerSpec`'s (centre, x right, y up, z out of
the print). Lengths in metres.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np

from asmteach.core import geometry
from asmteach.core.models import AssemblyTask, CameraIntrinsics, MarkerSpec, PartSpec, Primitive, SolidSpec
from asmteach.core.pose_error import PoseError, pose_error
from asmteach.plugins.detectors.aruco.markers import get_dictionary, marker_corners_part

if TYPE_CHECKING:
    from asmteach.plugins.detectors.aruco.teacher_settings import ArucoTeacherSettings

__all__ = ["SplitEstimate", "charuco_marker_poses", "solvepnp_split", "split_board_task", "teacher_split"]


def charuco_marker_poses(
    squares: tuple[int, int], square: float, marker: float, dictionary: str, *, legacy: bool = False
) -> dict[int, np.ndarray]:
    """``id -> T_board_marker`` of every marker of a ChArUco board (``squares`` along x and y).

    Taken from OpenCV's own layout (``CharucoBoard.getObjPoints``): the marker
    centre is the mean of its four corners, x runs from corner 0 to corner 1,
    y from corner 3 to corner 0 (OpenCV's corner order is top-left, top-right,
    bottom-right, bottom-left of the upright marker). ``legacy`` selects the
    pre-4.6 layout of boards with an even number of rows.
    """
    board = cv2.aruco.CharucoBoard(squares, square, marker, get_dictionary(dictionary))
    board.setLegacyPattern(legacy)
    poses = {}
    for mid, pts in zip(board.getIds().ravel(), board.getObjPoints(), strict=True):
        c = np.asarray(pts, dtype=np.float64).reshape(4, 3)
        x = (c[1] - c[0]) / np.linalg.norm(c[1] - c[0])
        y = (c[0] - c[3]) / np.linalg.norm(c[0] - c[3])
        poses[int(mid)] = geometry.from_rotation(np.column_stack([x, y, np.cross(x, y)]), c.mean(axis=0))
    return poses


def split_board_task(
    poses: dict[int, np.ndarray],
    ids_a: Sequence[int],
    ids_b: Sequence[int],
    T_A_B: np.ndarray,
    marker: float,
    dictionary: str,
    *,
    name: str = "board_split",
) -> AssemblyTask:
    """Two pseudo-parts made of one board's markers: A's frame is the board's, B's is ``T_A_B`` in it.

    Each marker of B gets ``T_B_marker = T_A_B^-1 T_board_marker``, so the
    teacher's estimate of B in A must come out as ``T_A_B``. The parts' solids
    are thin plates (only their markers matter here).
    """
    T_B_A = geometry.invert(T_A_B)
    plate = SolidSpec(add=[Primitive(shape="box", size=[0.2, 0.2, 0.001])])

    def part(part_name: str, ids: Sequence[int], T_part_board: np.ndarray) -> PartSpec:
        specs = [
            MarkerSpec(dictionary=dictionary, id=int(i), size=marker, T_part_marker=T_part_board @ poses[int(i)])
            for i in ids
        ]
        return PartSpec(name=part_name, solid=plate, markers=specs)

    return AssemblyTask(
        name=name, part_a=part("A", ids_a, np.eye(4)), part_b=part("B", ids_b, T_B_A), T_A_B=T_A_B, v_a=[0.0, 0.0, 1.0]
    )


@dataclass
class SplitEstimate:
    """An estimate of ``T_A_B`` from one photo and how it was made."""

    T_A_B: np.ndarray
    markers_a: list[int]
    markers_b: list[int]
    rms_px: float
    """RMS reprojection error over both groups' corners, pixels."""

    def errors(self, T_true: np.ndarray) -> PoseError:
        """The error of ``T_A_B`` against ``T_true`` (:func:`asmteach.core.pose_error.pose_error`)."""
        return pose_error(self.T_A_B, T_true)


def teacher_split(
    image: np.ndarray, camera: CameraIntrinsics, task: AssemblyTask, settings: ArucoTeacherSettings | None = None
) -> SplitEstimate:
    """``T_A_B`` from one photo the way the ArUco teacher sees each frame (:meth:`.ArucoTeacher.observe`:
    its detector and corner refinement, then :func:`.pnp.solve_part_pose`, one multi-marker PnP per part).
    ``ValueError`` when a group gets no pose."""
    from asmteach.plugins.detectors.aruco.teacher import ArucoTeacher
    from asmteach.plugins.detectors.aruco.teacher_settings import ArucoTeacherSettings

    teacher = ArucoTeacher(settings or ArucoTeacherSettings(), seed=0)
    r = teacher.observe([image], camera, task)[0]
    if r.T_A_B is None:
        raise ValueError(f"no pose for a group: A {r.pose_a is not None}, B {r.pose_b is not None}")
    return SplitEstimate(r.T_A_B, list(r.pose_a.marker_ids), list(r.pose_b.marker_ids), r.rms_px)


def solvepnp_split(
    image: np.ndarray, camera: CameraIntrinsics, task: AssemblyTask, *, refine: int = cv2.aruco.CORNER_REFINE_NONE
) -> SplitEstimate:
    """Baseline: OpenCV's ``ArucoDetector`` (default parameters, corner refinement ``refine``) and one plain
    ``cv2.solvePnP`` (``SOLVEPNP_ITERATIVE``) over all corners of each group."""
    dictionary = task.part_a.markers[0].dictionary
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = refine
    corners, ids, _ = cv2.aruco.ArucoDetector(get_dictionary(dictionary), params).detectMarkers(image)
    found = {int(i): np.asarray(c, dtype=np.float64).reshape(4, 2) for c, i in zip(corners, np.ravel(ids), strict=True)}
    K, dist = camera.K, camera.dist_array
    poses, used, sq, n = [], [], 0.0, 0
    for part in (task.part_a, task.part_b):
        mine = [m for m in part.markers if m.id in found]
        if not mine:
            raise ValueError(f"no marker of group {part.name} found")
        obj = np.concatenate([marker_corners_part(m) for m in mine])
        img = np.concatenate([found[m.id] for m in mine])
        _ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_ITERATIVE)
        proj, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
        sq += float(np.sum((proj.reshape(-1, 2) - img) ** 2))
        n += len(img)
        poses.append(geometry.from_rotation(cv2.Rodrigues(rvec)[0], tvec.ravel()))
        used.append([m.id for m in mine])
    return SplitEstimate(geometry.invert(poses[0]) @ poses[1], used[0], used[1], float(np.sqrt(sq / n)))
