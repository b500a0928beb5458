"""A second depth view settles what one view cannot: which of a detection's rival poses the other camera sees.

One view of a D peg turned about its axis with the flat out of sight, or of a near-square block, is explained
equally well by two poses (the detector lists them, ``details["ambiguous"]``). Another camera looking from
elsewhere sees the faces that tell them apart. :func:`judge_rivals` predicts, for each rival pose, the range
every ray of the other view should meet (the part at that pose, else the table plane) and compares it with the
range the camera measured, in units of the sensor's noise (:class:`KinectSettings`: axial noise at that range,
the disparity quantisation step, plus a pose allowance). Each ray costs ``min(r^2, c^2)`` (truncated so an edge
pixel or another object cannot outvote the rest; such rays cost the same under every pose and cancel). The best
pose wins only when every other rival costs more by a margin that is not noise: the per-ray cost differences
``d`` must sum to at least ``min_gain`` and to ``z_min`` times ``sqrt(sum d^2)`` (a paired test whose spread is
measured on the rays themselves), and the winner must explain the rays it predicts on the part
(``min_explained``). Otherwise the views stay ambiguous.

Frames: every cloud, viewpoint and pose in the world frame, metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from pydantic import Field

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core import geometry
from asmteach.core.models import StrictModel, TablePlane
from asmteach.core.perception.depth_camera import KinectSettings
from asmteach.core.perception.registration import ModelCloud, RefineSettings, icp_refine, model_cloud
from asmteach.core.perception.rival_turns import axis_turns, near_twins, own_symmetries, screw_turns
from asmteach.core.pose_error import pose_error

import open3d as o3d  # isort: skip  (after asmteach.core)

__all__ = [
    "DepthView",
    "SecondViewSettings",
    "ViewJudgement",
    "judge_rivals",
    "range_sigma",
    "ray_costs",
    "ray_inflation",
]


@dataclass(frozen=True)
class DepthView:
    """One depth view: its cloud ``(n, 3)`` and the camera centre ``(3,)`` (world frame, metres), and the sensor
    that took it (its noise model gives each ray's sigma; ``None``: the cell's Kinect, or the sensor the caller
    passes). A wrist camera's close, low-noise view weighs each ray by its own, smaller sigma."""

    cloud: np.ndarray
    viewpoint: np.ndarray | None
    sensor: KinectSettings | None = None


class SecondViewSettings(StrictModel):
    """How another view judges rival poses (noise units are the sensor's sigma at each ray's range)."""

    clip_sigmas: float = Field(3.0, gt=0.0, description="a ray's residual costs at most this many sigmas, squared")
    pose_sigma: float = Field(
        0.001, ge=0.0, description="metres added (in quadrature) to the sensor noise: the rivals were fit to one view"
    )
    z_min: float = Field(
        5.0, gt=0.0, description="the cost gap must be this many times its own spread over the rays (paired test)"
    )
    min_gain: float = Field(50.0, gt=0.0, description="least cost gap (sum of squared sigmas) a winner needs")
    min_explained: float = Field(
        0.6, ge=0.0, le=1.0, description="least share of the rays a winner puts on the part that it explains"
    )
    margin: float = Field(0.01, ge=0.0, description="rays passing this far (metres) around the part are judged")
    step_deg: float = Field(10.0, gt=0.0, le=90.0, description="turns about the rivals' screw axis tried, degrees")
    turned_rivals: int = Field(3, ge=1, description="the first this many rivals are turned all round")
    refine_top: int = Field(
        16,
        ge=1,
        description="cheapest grid candidates refined and compared with the rivals: the grid only finds the basins, "
        "and a basin none of them falls in is never compared (8 missed the truth's on keyed_peg_2 scene 0 seen by "
        "four stacked Kinect frames and a wrist look, and settled a pose 85 deg off at z 8.4; 16 settle it 0.19 deg "
        "off at z 22)",
    )
    polish_mm: float = Field(
        0.5, ge=0.0, description="first step (mm) of the search that moves each refined candidate to its least ray cost"
    )
    polish_deg: float = Field(0.5, ge=0.0, description="... and its first turn, degrees")
    polish_halvings: int = Field(3, ge=0, description="times the steps are halved (3: down to 0.06 mm / 0.06 deg)")
    polish_sweeps: int = Field(
        10, ge=1, description="most sweeps over the six axes at each step size (bounds its time)"
    )
    distinct_mm: float = Field(5.0, gt=0.0, description="a candidate this far from the winner must lose, mm")
    distinct_deg: float = Field(5.0, gt=0.0, description="... or turned this far from it, degrees")
    twin_mm: float = Field(
        1.5, ge=0.0, description="a turn moving the part's surface this little on average (mm) makes a near twin"
    )
    block_mm: float = Field(
        1.0,
        ge=0.0,
        description="neighbouring rays in squares this wide (mm, across the view at the part) whose misfits move "
        "together under the best pose count as fewer independent rays in the paired test's spread (0: none do)",
    )


@dataclass
class ViewJudgement:
    """What the views say about rival poses: ``winner`` (index into the rivals, -1 for another pose) or ``None``."""

    winner: int | None
    costs: list[float]
    """Total cost of each rival, then of the winner, over every judged ray of every view (squared sigmas)."""
    gains: list[float]
    """Cost gap of each rival over the best one (0 for the best)."""
    z: list[float]
    """Gap over its spread, per rival (inf for the best)."""
    explained: float
    """Share of the rays the best pose puts on the part that it explains (within ``clip_sigmas``)."""
    rays: int
    why: str | None = None
    pose: np.ndarray | None = None
    """The cheapest candidate (``T_world_part``), refined on every view: the pose reported when it wins."""
    candidates: int = 0
    weakest_gain: float | None = None
    """Cost gap of the cheapest candidate distinct from the winner (squared sigmas)."""
    weakest_z: float | None = None
    rival_pose: np.ndarray | None = None
    inflation: float = 1.0
    """How many rays count as one independent ray in the spread (:func:`ray_inflation`)."""
    """That candidate (``T_world_part``, refined): with ``pose``, the pair a further view should tell apart."""

    def as_details(self) -> dict:
        """JSON-ready summary for ``Detection.details``."""
        return {
            "winner": self.winner,
            "costs": [round(c, 1) for c in self.costs],
            "gains": [round(g, 1) for g in self.gains],
            "z": [round(z, 2) if np.isfinite(z) else None for z in self.z],
            "explained": round(self.explained, 3),
            "rays": self.rays,
            "candidates": self.candidates,
            "closest_rival_gain": None if self.weakest_gain is None else round(self.weakest_gain, 1),
            "closest_rival_z": None if self.weakest_z is None else round(self.weakest_z, 2),
            "best_T_world_part": None if self.pose is None else np.asarray(self.pose).tolist(),
            "ray_inflation": round(self.inflation, 2),
            "closest_rival_T_world_part": None if self.rival_pose is None else np.asarray(self.rival_pose).tolist(),
        }


def range_sigma(rng: np.ndarray, sensor: KinectSettings, pose_sigma: float) -> np.ndarray:
    """Per-ray std (metres) of the measured range ``rng``: axial noise, quantisation step / sqrt(12), pose."""
    var = np.full(rng.shape, pose_sigma**2)
    if sensor.axial_noise:
        var += sensor.axial_sigma(rng) ** 2
    if sensor.quantize:
        step = rng**2 / (sensor.baseline * sensor.fx * sensor.disparity_subpixel)
        var += step**2 / 12.0
    return np.sqrt(var)


def _in_cone(view: DepthView, centers: np.ndarray, radius: float) -> np.ndarray:
    """Mask of the view's points whose rays pass within the sphere that holds every sphere of ``radius``
    about ``centers`` (the candidates turn about the part's centre: one sphere does), and that do not lie in
    front of it (an occluder there is no evidence either way)."""
    eye = np.asarray(view.viewpoint, float)
    c = np.asarray(centers, float).mean(axis=0)
    radius = radius + float(np.max(np.linalg.norm(np.asarray(centers, float) - c, axis=1)))
    d = np.asarray(view.cloud, float) - eye
    rng = np.linalg.norm(d, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        along = (d @ (c - eye)) / rng
    off2 = float((c - eye) @ (c - eye)) - along**2
    return np.isfinite(along) & (rng > 1e-6) & (off2 <= radius**2) & (rng >= along - radius)


def _near_rays(view: DepthView, centers: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """``(unit directions, measured ranges)`` of the view's rays in :func:`_in_cone`."""
    d = np.asarray(view.cloud, float)[_in_cone(view, centers, radius)] - np.asarray(view.viewpoint, float)
    rng = np.linalg.norm(d, axis=1)
    return d / rng[:, None], rng


def _ray_blocks(view: DepthView, centers: np.ndarray, radius: float, block_m: float) -> np.ndarray:
    """Block index of each of the view's rays in :func:`_in_cone` (the order of :func:`_near_rays`): the square of
    side ``block_m`` (metres, in the plane across the view through the candidates' centre) each ray crosses."""
    eye = np.asarray(view.viewpoint, float)
    u, _ = _near_rays(view, centers, radius)
    c = np.asarray(centers, float).mean(axis=0) - eye
    dist = float(np.linalg.norm(c))
    a = c / dist
    e1 = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    along = np.maximum(u @ a, 1e-6)
    ij = np.floor(np.c_[u @ e1, u @ e2] * (dist / along)[:, None] / block_m).astype(np.int64)
    return np.unique(ij, axis=0, return_inverse=True)[1].reshape(-1)


def _predicted_ranges(
    scene: o3d.t.geometry.RaycastingScene, T_world_part: np.ndarray, eye: np.ndarray, u: np.ndarray, table: TablePlane
) -> tuple[np.ndarray, np.ndarray]:
    """``(range, on_part)``: where each ray from ``eye`` along ``u`` first meets the part or the table plane."""
    T_pw = geometry.invert(T_world_part)
    eye_p = T_pw[:3, :3] @ eye + T_pw[:3, 3]
    rays = np.hstack([np.broadcast_to(eye_p, u.shape), u @ T_pw[:3, :3].T]).astype(np.float32)
    t_part = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().astype(float)
    n = np.asarray(table.normal, float)
    denom = u @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t_table = (table.height - float(n @ eye)) / denom
    t_table = np.where((denom < -1e-9) & (t_table > 0), t_table, np.inf)
    return np.minimum(t_part, t_table), t_part < t_table


@dataclass(frozen=True)
class _Rays:
    """One view's rays near the candidates: camera centre, unit directions, measured ranges and their sigmas
    (world frame, metres)."""

    eye: np.ndarray
    u: np.ndarray
    measured: np.ndarray
    sigma: np.ndarray


def _rays(
    model: ModelCloud, view: DepthView, around: list[np.ndarray], sensor: KinectSettings | None, s: SecondViewSettings
) -> _Rays:
    """The rays of ``view`` near any pose of ``around`` (the noise model: ``view.sensor``, else ``sensor``, else
    the cell's Kinect)."""
    centers = np.array([geometry.transform_points(T, model.center[None])[0] for T in around])
    u, measured = _near_rays(view, centers, model.radius + s.margin)
    sigma = range_sigma(measured, view.sensor or sensor or KinectSettings(), s.pose_sigma)
    return _Rays(np.asarray(view.viewpoint, float), u, measured, sigma)


def _costs_on(
    model: ModelCloud, T: np.ndarray, rays: _Rays, table: TablePlane, s: SecondViewSettings
) -> tuple[np.ndarray, np.ndarray]:
    """``(cost, on_part)`` of every ray of ``rays`` with the part at ``T`` (``T_world_part``)."""
    pred, on_part = _predicted_ranges(model.scene, np.asarray(T, float), rays.eye, rays.u, table)
    r = np.where(np.isfinite(pred), (rays.measured - pred) / rays.sigma, np.inf)
    return np.minimum(r * r, s.clip_sigmas**2), on_part


def ray_costs(
    model: ModelCloud,
    poses: list[np.ndarray],
    view: DepthView,
    table: TablePlane,
    sensor: KinectSettings | None = None,
    settings: SecondViewSettings | None = None,
    around: list[np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(costs (k, m), on_part (k, m))`` of the part (``model``: its ray-casting scene and bounding sphere,
    :func:`~asmteach.core.perception.registration.model_cloud`) at ``k`` poses on the ``m`` rays of ``view`` near
    any of them (or near any pose of ``around``, so that poses scored in several calls share the rays).

    A ray's cost is its squared residual (measured minus predicted range) in sigmas, clipped at
    ``clip_sigmas``; ``on_part`` says the pose puts the part (not the table) first on that ray. The noise model is
    the view's own sensor (``view.sensor``), else ``sensor``, else the cell's Kinect.
    """
    s = settings or SecondViewSettings()
    rays = _rays(model, view, around or poses, sensor, s)
    costs = np.empty((len(poses), len(rays.u)))
    on_part = np.empty((len(poses), len(rays.u)), dtype=bool)
    for i, T in enumerate(poses):
        costs[i], on_part[i] = _costs_on(model, T, rays, table, s)
    return costs, on_part


def _polish(
    model: ModelCloud, T: np.ndarray, rays: list[_Rays], table: TablePlane, s: SecondViewSettings
) -> np.ndarray:
    """``T`` moved to the least total ray cost near it: a pattern search (steps along and about the world axes
    through the part's centre, halved when none lowers the cost) on the very cost the poses are compared by.

    ICP on the points cannot do it: where the views see one flat face, only the outline pins the turn and the
    shift, and an outline is rays that meet the table or the part, a cost with no gradient. ICP left the truth's
    candidate of ff_stone 1 (a square slab seen from above, four Kinect frames and a wrist look) 0.86 mm /
    0.9 deg off at 2900 sigma^2 over its basin's floor, and a pose turned 90 deg won at z 12.6; polished, the
    two are 40 sigma^2 apart and the views rightly stay ambiguous.
    """
    T = np.asarray(T, float)
    if s.polish_mm <= 0.0 and s.polish_deg <= 0.0:
        return T

    def cost(P: np.ndarray) -> float:
        return float(sum(_costs_on(model, P, r, table, s)[0].sum() for r in rays))

    best = cost(T)
    step_m, step_rad = s.polish_mm / 1000.0, np.radians(s.polish_deg)
    for _ in range(s.polish_halvings + 1):
        # sweeps over the six axes, each moved one step either way when that lowers the cost, until a sweep
        # moves nothing (or polish_sweeps of them); then the steps are halved
        for _ in range(s.polish_sweeps):
            moved = False
            for k in range(6):
                c = geometry.transform_points(T, model.center[None])[0]
                for sign in (1.0, -1.0):
                    if k < 3:
                        D = geometry.from_rotation(np.eye(3), sign * step_m * np.eye(3)[k])
                    else:
                        R = geometry.from_rotvec(sign * step_rad * np.eye(3)[k - 3])[:3, :3]
                        D = geometry.from_rotation(R, c - R @ c)
                    trial = cost(D @ T)
                    if trial < best:
                        T, best, moved = D @ T, trial, True
                        break
            if not moved:
                break
        step_m, step_rad = step_m / 2.0, step_rad / 2.0
    return T


def _fused_refine(model: ModelCloud, T: np.ndarray, views: list[DepthView], table: TablePlane) -> np.ndarray:
    """``T`` refined by point-to-plane ICP on the points every view saw near the part's surface above the table."""
    from scipy.spatial import cKDTree

    tree = cKDTree(geometry.transform_points(T, model.points))
    n = np.asarray(table.normal, float)
    segs = []
    for v in views:
        pts = np.asarray(v.cloud, float)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        d, _ = tree.query(pts, distance_upper_bound=0.01)
        segs.append(pts[np.isfinite(d) & (pts @ n > table.height + 0.002)])
    seg = np.vstack(segs)
    if len(seg) < 30:
        return T
    return icp_refine(seg, model, T, RefineSettings())


def judge_rivals(
    mesh: trimesh.Trimesh,
    poses: list[np.ndarray],
    views: list[DepthView],
    table: TablePlane,
    symmetries: np.ndarray | list[np.ndarray] | None = None,
    sensor: KinectSettings | None = None,
    settings: SecondViewSettings | None = None,
) -> ViewJudgement:
    """Which pose every view (the first one included) clearly prefers among ``poses`` and their turns, if any.

    ``poses`` (``T_world_part``) are the rivals one view could not tell apart (best first). The candidates
    are they, the first turned all round about the screw axis to each other one (:func:`screw_turns`) and
    each turned all round about the part's principal axes (:func:`axis_turns`), every ``step_deg``: the truth
    need not be one of the poses listed. Each is scored on the rays of every view. The cheapest, refined by
    ICP on the points every view saw of it and then moved to the least ray cost near it (:func:`_polish`: every
    pose compared sits at the floor of its basin, so none loses for want of refinement), wins when every
    candidate distinct from it (beyond ``distinct_mm`` / ``distinct_deg``, up to the part's ``symmetries``, part
    frame; computed when ``None``) costs more by the margin. ``winner`` indexes ``poses`` when the winner is
    within the tolerance of one of them, else it is ``-1`` and ``pose`` holds it.
    """
    s = settings or SecondViewSettings()
    usable = [v for v in views if v.viewpoint is not None and len(v.cloud)]
    if len(poses) < 2 or len(usable) < 2:
        return ViewJudgement(None, [], [], [], 0.0, 0, "fewer than two views with a camera centre")
    syms = own_symmetries(mesh) if symmetries is None else np.asarray(symmetries, float).reshape(-1, 4, 4)
    cands = [np.asarray(T, float) for T in poses]
    # turns of the leading rivals only: a hull-twin ambiguity may list dozens of poses (a soccer ball), and
    # turning each of them all round cost minutes of ray casting for nothing the listed poses do not cover
    for T in poses[1 : s.turned_rivals]:
        cands += screw_turns(cands[0], np.asarray(T, float), s.step_deg)
    for T in poses[: s.turned_rivals]:
        cands += axis_turns(mesh, np.asarray(T, float), s.step_deg)
    model = model_cloud(mesh, 4000)
    centers = np.array([geometry.transform_points(T, model.center[None])[0] for T in cands])
    radius = model.radius + s.margin
    # every step below needs only the points around the part: crop each view once (a frame holds 300 000)
    usable = [
        DepthView(np.asarray(v.cloud, float)[_in_cone(v, centers, radius)], v.viewpoint, v.sensor) for v in usable
    ]
    rays = [_rays(model, v, cands, sensor, s) for v in usable]  # every pose below is scored on these rays
    raw, _ = _all_costs(model, cands, rays, table, s)
    raw_total = raw.sum(axis=1)
    # The grid only finds the basins: the poses compared are the rivals and the cheapest candidates, each
    # refined on every view, so that a neighbour a grid step away is not taken for a rival.
    seeds = list(range(len(poses))) + [int(i) for i in np.argsort(raw_total)[: s.refine_top] if i >= len(poses)]
    # the rivals as listed stay in the pool: when every refined pose falls on one, the listed rivals still
    # have to lose by the margin (the comparison is never empty)
    pool = _polished(
        model, [_fused_refine(model, cands[i], usable, table) for i in seeds] + cands[: len(poses)], rays, table, s
    )
    costs, on_part = _all_costs(model, pool, rays, table, s)
    best = int(np.argmin(costs.sum(axis=1)))
    # The best pose's near twins must lose too: a twin differs only where a view may not look (a blind hole
    # facing the table) and the grid's cheapest need not reach its basin (a close view's sub-mm sigma makes a
    # grid pose 0.6 deg off cost more than a wrong basin's; d_peg 1 seed 9 settled a block 180 deg off).
    twins = [pool[best] @ S for S in near_twins(mesh, s.step_deg, s.twin_mm)]
    if twins:
        pool += _polished(model, [_fused_refine(model, T, usable, table) for T in twins], rays, table, s)
        costs, on_part = _all_costs(model, pool, rays, table, s)
        best = int(np.argmin(costs.sum(axis=1)))
    # The winner's own misfit measures how far neighbouring rays are independent evidence: a close view's
    # neighbours misfit together (an edge a fraction of a millimetre off, a hole wall's shade), so each ray's cost
    # difference counts as 1 / inflation of a ray (keyed_peg 2 seed 9's block passed at z 5.85 on single rays).
    inflation = ray_inflation(costs[best], _all_blocks(model, usable, s, cands))
    cands = pool
    total = costs.sum(axis=1)
    gains, zs = [], []
    weakest = None
    for i, T in enumerate(cands):
        d = costs[i] - costs[best]
        spread = float(np.sqrt(np.sum(d * d) * inflation))
        gains.append(float(d.sum()))
        zs.append(gains[-1] / spread if spread > 0 else 0.0)
        if i != best and not pose_error(T, cands[best], right=syms).within(s.distinct_mm, s.distinct_deg):
            if weakest is None or (gains[i], zs[i]) < (gains[weakest], zs[weakest]):
                weakest = i
    mine = on_part[best]
    explained = float(np.mean(costs[best][mine] < s.clip_sigmas**2)) if mine.any() else 0.0
    why = None
    if weakest is not None and (gains[weakest] < s.min_gain or zs[weakest] < s.z_min):
        mm, deg = _apart(cands[weakest], cands[best], syms)
        why = (
            f"no pose is clearly preferred: one {mm:.0f} mm and {deg:.0f} deg away costs {gains[weakest]:.0f} "
            f"sigma^2 more, {zs[weakest]:.1f} times its spread (needs {s.min_gain:.0f} and {s.z_min:.0f})"
        )
    elif explained < s.min_explained:
        need = 100 * s.min_explained
        why = f"the best pose explains {100 * explained:.0f} % of the rays on it (needs {need:.0f} %)"
    near = [
        i for i, T in enumerate(poses) if pose_error(T, cands[best], right=syms).within(s.distinct_mm, s.distinct_deg)
    ]
    return ViewJudgement(
        winner=None if why else (near[0] if near else -1),
        costs=[float(raw_total[i]) for i in range(len(poses))] + [float(total[best])],
        gains=[float(raw_total[i] - total[best]) for i in range(len(poses))],
        z=[zs[i] if i != best else float("inf") for i in range(len(poses))],  # the rivals refined
        explained=explained,
        rays=int(costs.shape[1]),
        why=why,
        pose=cands[best],
        candidates=len(raw_total),
        weakest_gain=None if weakest is None else gains[weakest],
        weakest_z=None if weakest is None else zs[weakest],
        rival_pose=None if weakest is None else cands[weakest],
        inflation=inflation,
    )


def _polished(
    model: ModelCloud, poses: list[np.ndarray], rays: list[_Rays], table: TablePlane, s: SecondViewSettings
) -> list[np.ndarray]:
    """``poses`` each :func:`_polish`-ed, less any that fall within 0.5 mm and 0.5 deg of an earlier one (refined
    grid neighbours end in the same basin; searching it again costs time and adds nothing)."""
    out: list[np.ndarray] = []
    for T in poses:
        if any(
            geometry.translation_distance(T, P) < 5e-4 and geometry.rotation_distance(T, P) < np.radians(0.5)
            for P in out
        ):
            continue
        out.append(T)
    return [_polish(model, T, rays, table, s) for T in out]


def _apart(A: np.ndarray, B: np.ndarray, syms: np.ndarray) -> tuple[float, float]:
    err = pose_error(A, B, right=syms)
    return err.position_mm, err.angle_deg


def _all_costs(
    model: ModelCloud, poses: list[np.ndarray], rays: list[_Rays], table: TablePlane, s: SecondViewSettings
) -> tuple[np.ndarray, np.ndarray]:
    """Ray costs ``(k, m)`` and on-part flags of ``poses`` over every view's ``rays``, side by side."""
    parts = [[_costs_on(model, T, r, table, s) for r in rays] for T in poses]
    costs = np.array([np.concatenate([c for c, _ in row]) for row in parts]).reshape(len(poses), -1)
    on_part = np.array([np.concatenate([o for _, o in row]) for row in parts]).reshape(len(poses), -1)
    return costs, on_part


def _all_blocks(
    model: ModelCloud, views: list[DepthView], s: SecondViewSettings, around: list[np.ndarray]
) -> np.ndarray:
    """Block index of every ray :func:`_all_costs` scores (views side by side, no block shared by two views; each
    ray its own block when ``block_mm`` is 0)."""
    centers = np.array([geometry.transform_points(T, model.center[None])[0] for T in around])
    radius = model.radius + s.margin
    out, first = [], 0
    for v in views:
        if s.block_mm > 0.0:
            b = _ray_blocks(v, centers, radius, s.block_mm / 1000.0)
        else:
            b = np.arange(int(np.count_nonzero(_in_cone(v, centers, radius))))
        out.append(b + first)
        first += int(b.max()) + 1 if len(b) else 0
    return np.concatenate(out) if out else np.empty(0, np.int64)


def ray_inflation(costs: np.ndarray, blocks: np.ndarray) -> float:
    """How much neighbouring rays' costs move together (>= 1): the variance of the per-block sums of ``costs``
    (one pose's per-ray costs, centred; ``blocks`` a block index per ray) over the variance their rays would give
    alone. ``n / inflation`` is the effective number of independent rays; 1 when rays misfit independently."""
    if len(costs) < 2:
        return 1.0
    c = costs - costs.mean()
    alone = float(np.sum(c * c))
    if alone <= 0.0:
        return 1.0
    per_block = np.bincount(blocks, weights=c)
    return max(1.0, float(np.sum(per_block * per_block)) / alone)
