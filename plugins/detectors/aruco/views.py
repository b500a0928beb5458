"""Where the demonstration's camera looks from, and which markers a detector can use in a rendered frame.

:func:`choose_views` picks viewing poses around an assembly from which both
parts show markers (and, given the approach length, keep showing one each
while B approaches A); :func:`usable_markers` says which markers of a
rendered frame count as seen (unoccluded, not edge-on, large enough), the
rule the demonstration's hands and the view choice share. Metres, A's frame
for poses (``T_cam_A``).
"""

from __future__ import annotations

import heapq
import itertools

import numpy as np

from asmteach.core import geometry
from asmteach.core.interfaces import PartModel
from asmteach.core.models import AssemblyTask, CameraIntrinsics
from asmteach.plugins.detectors.aruco.render import Rendered, RenderObject, render_scene

__all__ = ["USABLE_AREA_PX", "USABLE_FACING", "assembly_centre", "choose_views", "usable_markers"]


def _look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """``T_A_cam`` of a camera at ``eye`` looking at ``target`` (OpenCV axes: y down)."""
    z = target - eye
    z = z / np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-6:
        x = np.cross(z, np.array([1.0, 0.0, 0.0]))
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    return geometry.from_rotation(np.column_stack([x, y, z]), eye)


def _fibonacci_sphere(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5**0.5) * i
    return np.column_stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)])


def assembly_centre(a: PartModel, b: PartModel, T_A_B: np.ndarray) -> np.ndarray:
    """Centre of the assembled pair's bounding box, in A's frame (metres)."""
    pts = np.vstack([a.mesh.vertices, geometry.transform_points(T_A_B, b.mesh.vertices)])
    return 0.5 * (pts.min(axis=0) + pts.max(axis=0))


def choose_views(
    a: PartModel,
    b: PartModel,
    task: AssemblyTask,
    camera: CameraIntrinsics,
    distance: float,
    count: int = 5,
    approach_length: float = 0.0,
) -> list[np.ndarray]:
    """``count`` viewing poses ``T_cam_A`` from which both parts show markers, mutually >= 30 deg apart.

    Candidate directions on a sphere around the assembly are ranked by how
    squarely and how fully (rendered visibility, occlusion by the other part
    included) each part's best two markers are seen; the worse part decides.
    With an ``approach_length`` (metres), views where each part also keeps a
    wholly visible marker while B is that far and half as far back along
    ``v_a`` come first, as a person filming the approach would hold the
    camera: a B held above A can hide A's only markers from a view that sees
    both well once assembled (a cap over the markers beside its post).
    """
    centre = assembly_centre(a, b, task.T_A_B)
    dirs = _fibonacci_sphere(400)
    mk = [(m, "A", m.T_part_marker) for m in a.spec.markers] + [
        (m, "B", task.T_A_B @ m.T_part_marker) for m in b.spec.markers
    ]
    normals = np.array([T[:3, 2] for _, _, T in mk])
    cos = dirs @ normals.T  # how squarely each marker faces the camera direction

    def part_score(c: np.ndarray, role: str) -> float:
        vals = sorted((c[i] for i, (_, r, _) in enumerate(mk) if r == role and c[i] > 0.35), reverse=True)
        return float(sum(vals[:2]))

    pre = np.array([min(part_score(c, "A"), part_score(c, "B")) for c in cos])
    order = [int(i) for i in np.argsort(-pre)[:60] if pre[i] > 0]
    K = camera.K
    bg = np.zeros((camera.height, camera.width, 3), np.float32)

    def view_score(idx: int) -> tuple[float, np.ndarray]:
        u = dirs[idx]
        up = np.array([0.0, 0.0, 1.0]) if abs(u[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
        T_cam_A = geometry.invert(_look_at(centre + distance * u, centre, up))
        r = render_scene(
            [
                RenderObject(a.mesh, a.spec.color, a.spec.markers, T_cam_A),
                RenderObject(b.mesh, b.spec.color, b.spec.markers, T_cam_A @ task.T_A_B),
            ],
            K,
            camera.width,
            camera.height,
            background=bg,
            supersample=1,
        )
        vis = np.zeros(len(mk))
        for i, (m, _, _) in enumerate(mk):
            area = r.marker_area.get(m.id, 0.0)
            if area > 0 and r.marker_pixels.get(m.id, 0.0) >= 0.995 * area and cos[idx, i] > 0.35:
                vis[i] = cos[idx, i] * min(1.0, area / 400.0)
        score = min(
            float(sum(sorted((vis[i] for i in range(len(mk)) if mk[i][1] == role), reverse=True)[:2]))
            for role in ("A", "B")
        )
        return score, T_cam_A

    # The candidates by rendered score (ties in ``order``'s order), drawn lazily: a rendered score never
    # exceeds the facing-only score ``pre`` (each marker's term only loses visibility and size), so a drawn
    # candidate is ranked for good once no candidate left to draw has a higher ``pre``.
    scored: list[tuple[float, int, np.ndarray]] = []
    drawn: list[tuple[float, int, int, np.ndarray]] = []  # heap of (-score, rank in order, idx, T_cam_A)
    left = iter(enumerate(order))
    nxt = next(left, None)

    def ranked(k: int) -> tuple[float, int, np.ndarray] | None:
        nonlocal nxt
        while len(scored) <= k:
            bound = pre[nxt[1]] if nxt is not None else -np.inf
            if drawn and -drawn[0][0] >= bound:
                neg, _, idx, T = heapq.heappop(drawn)
                scored.append((-neg, idx, T))
            elif nxt is not None:
                score, T = view_score(nxt[1])
                heapq.heappush(drawn, (-score, nxt[0], nxt[1], T))
                nxt = next(left, None)
            else:
                return None
        return scored[k]

    approach_ok: dict[int, bool] = {}

    def shows_approach(idx: int, T_cam_A: np.ndarray) -> bool:
        if idx not in approach_ok:
            approach_ok[idx] = all(
                _both_parts_seen(a, b, task, T_cam_A, frac * approach_length, camera) for frac in (1.0, 0.5)
            )
        return approach_ok[idx]

    chosen: list[tuple[int, np.ndarray]] = []
    for need_approach in (True, False) if approach_length > 0 else (False,):
        for min_sep in (30.0, 15.0, 0.0):
            for k in itertools.count():
                item = ranked(k) if len(chosen) < count else None
                if item is None or item[0] <= 0:
                    break
                _score, idx, T = item
                if any(j == idx for j, _ in chosen):
                    continue
                if all(np.degrees(np.arccos(np.clip(dirs[idx] @ dirs[j], -1, 1))) >= min_sep for j, _ in chosen) and (
                    not need_approach or shows_approach(idx, T)
                ):
                    chosen.append((idx, T))
            if len(chosen) == count:
                break
        if len(chosen) == count:
            break
    if not chosen:
        raise ValueError(f"no viewing direction shows markers of both parts of {task.name!r}")
    while len(chosen) < count:
        chosen.append(chosen[len(chosen) % max(1, len(chosen))])
    return [T for _, T in chosen]


def _both_parts_seen(
    a: PartModel, b: PartModel, task: AssemblyTask, T_cam_A: np.ndarray, back: float, camera: CameraIntrinsics
) -> bool:
    """Whether each part shows a wholly visible marker facing the camera with B ``back`` metres back along
    ``v_a`` from its assembled pose (the parts' mutual occlusion included)."""
    T_A_B = task.T_A_B.copy()
    T_A_B[:3, 3] -= back * np.asarray(task.v_a, float)
    r = render_scene(
        [
            RenderObject(a.mesh, a.spec.color, a.spec.markers, T_cam_A),
            RenderObject(b.mesh, b.spec.color, b.spec.markers, T_cam_A @ T_A_B),
        ],
        camera.K,
        camera.width,
        camera.height,
        background=np.zeros((camera.height, camera.width, 3), np.float32),
        supersample=1,
    )

    usable = usable_markers(r)
    return any(m.id in usable for m in a.spec.markers) and any(m.id in usable for m in b.spec.markers)


USABLE_FACING = 0.5
"""A marker seen more than 60 deg off square-on is too foreshortened to detect reliably."""
USABLE_AREA_PX = 200.0
"""Nor is one whose black square covers fewer pixels (about 14 x 14: 2.4 px per cell of a 4x4 marker)."""


def usable_markers(r: Rendered) -> set[int]:
    """Ids of the markers of a rendered frame a detector can use: >= 98 % of the square unoccluded by the parts,
    facing the camera within 60 deg and at least ``USABLE_AREA_PX`` pixels."""
    return {
        i
        for i, area in r.marker_area.items()
        if area >= USABLE_AREA_PX
        and r.marker_pixels.get(i, 0.0) >= 0.98 * area
        and r.marker_facing.get(i, 0.0) >= USABLE_FACING
    }
