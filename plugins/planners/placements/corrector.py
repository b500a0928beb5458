"""The ``stable_placements`` corrector: snap a rough pose onto a stable placement, then refine.

Paper, Alg. "Noise correction", with its line 4 fixed: each placement
rotation is compared with the *raw* rotation ``R_r`` (the printed ``R_p'`` is
a typo) by geodesic distance on SO(3). Placements are defined up to a yaw
about the table normal, so placement ``i`` is compared in the yaw that brings
it closest to ``R_r``: ``d_i = min_psi |log((Rz(psi) R_p(i))^T R_r)|`` (closed
form; with ``yaw_from: rpy`` the paper's ``psi = yaw(R_r)`` is used instead).
The corrected rotation is ``R_c = Rz(psi) R_near``: the raw yaw is kept and
roll and pitch are exactly the placement's. The part is then put on the
table: its lowest point at the table height, and its centre of mass (or, as in
the paper, its origin) kept at the raw x, y.

Beyond the paper: a planar ICP (x, y, yaw; :mod:`.planar_icp`) of the model
against the observed cloud, from several yaw starts, and a choice among the
equivalent poses of a rotationally symmetric placement. When the camera
centre is known (``viewpoint`` argument or setting) the ICP also matches the
model surface the camera can see at each pose against the cloud, so the part
cannot slide along an axis whose ends are seen edge-on. The table comes from
the given :class:`TablePlane`, or is fitted to the cloud (Open3D RANSAC) when
none is given or ``table: fit``.

Frames: ``T_world_part`` in, ``T_world_part`` out (metres); internally the
table frame of :func:`.table.table_frame`.
"""

from __future__ import annotations

import time
import warnings
from typing import Any, Literal

import numpy as np
from pydantic import Field

from asmteach.core import geometry
from asmteach.core.errors import UserError
from asmteach.core.interfaces import Corrector, PartModel
from asmteach.core.models import Correction, StrictModel, TablePlane, Vec3
from asmteach.core.rests.placements import PlacementResult, placement_result
from asmteach.plugins.planners.placements.planar_icp import ModelSurface, planar_icp, planar_transform
from asmteach.plugins.planners.placements.table import fit_table_plane, points_above, table_frame

__all__ = ["StablePlacementCorrector", "nearest_placement"]


def _rz(psi: np.ndarray) -> np.ndarray:
    """``(k, 3, 3)`` rotations about z by the angles ``psi`` (radians)."""
    c, s = np.cos(psi), np.sin(psi)
    R = np.zeros((len(psi), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    return R


def _angle(R: np.ndarray) -> np.ndarray:
    """Rotation angles (radians) of ``(k, 3, 3)`` matrices, stable near 0 and pi."""
    cos = np.clip((np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    skew = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=1)
    return np.arctan2(np.linalg.norm(skew, axis=1) / 2.0, cos)


def nearest_placement(
    R_raw: np.ndarray, placement_rotations: np.ndarray, *, yaw_from: str = "geodesic"
) -> tuple[np.ndarray, np.ndarray]:
    """Geodesic distance (radians) of ``R_raw`` to each placement, and the yaw used for each.

    ``placement_rotations`` is ``(k, 3, 3)`` (table frame, canonical yaw). With
    ``yaw_from="geodesic"`` the yaw ``psi`` maximises ``trace((Rz(psi) R_p)^T R_raw)``,
    i.e. ``Rz(psi) R_p`` is the point of the placement's yaw orbit nearest to ``R_raw``
    (``psi = atan2(M10 - M01, M00 + M11)`` with ``M = R_raw R_p^T``); with ``"rpy"``
    it is the paper's ``yaw(R_raw) - yaw(R_p)`` (fixed-axis rpy).
    """
    Rp = np.asarray(placement_rotations, dtype=float)
    M = np.einsum("ij,kjl->kil", R_raw, np.transpose(Rp, (0, 2, 1)))
    if yaw_from == "geodesic":
        psi = np.arctan2(M[:, 1, 0] - M[:, 0, 1], M[:, 0, 0] + M[:, 1, 1])
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # scipy warns at gimbal lock; the yaw is still defined
            psi = np.array([geometry.yaw_of(R_raw) - geometry.yaw_of(R) for R in Rp])
    Rc = np.einsum("kij,kjl->kil", _rz(psi), Rp)
    d = _angle(np.einsum("kji,jl->kil", Rc, R_raw))
    return d, psi


class StablePlacementCorrector(Corrector):
    """Snap to the nearest stable placement, keep the raw yaw, rest on the table, refine x, y, yaw."""

    class Settings(StrictModel):
        """Settings of the ``stable_placements`` corrector."""

        min_margin: float = Field(0.1, ge=0.0, description="stability margin d / h of a placement")
        angle_tol_deg: float = Field(1.0, gt=0.0, le=10.0, description="coplanar-face clustering tolerance, degrees")
        max_snap_deg: float = Field(
            8.0,
            gt=0.0,
            description="a rough pose farther than this (degrees) from every placement with min_margin goes to the "
            "nearest rest with a smaller margin (>= marginal_margin) when that one is nearer: a part can rest where "
            "d / h < min_margin (a headed pin on its head's edge and its shank's tip, d / h 0.05), and snapping it "
            "to the nearest robust placement turned a pose 3 deg off into one 16.6 deg off",
        )
        marginal_margin: float = Field(
            0.01, ge=0.0, description="least margin d / h of a rest a far rough pose may be snapped to"
        )
        yaw_from: Literal["geodesic", "rpy"] = Field(
            "geodesic", description="yaw kept from the raw pose: nearest on SO(3), or the paper's rpy yaw"
        )
        pivot: Literal["com", "origin"] = Field(
            "com", description="point kept at the raw x, y when snapping: centre of mass, or the paper's origin"
        )
        table: Literal["given", "fit"] = Field(
            "given", description="use the given table plane, or fit it to the cloud (also when none is given)"
        )
        refine: bool = Field(True, description="planar ICP (x, y, yaw) against the cloud when one is given")
        min_cloud_points: int = Field(30, ge=6, description="fewer part points than this skip the refinement")
        table_band: float = Field(0.002, ge=0.0, description="metres; points this close to the table are ignored")
        icp_max_correspondence: float = Field(0.02, gt=0.0, description="metres, first ICP inlier radius")
        icp_min_correspondence: float = Field(0.003, gt=0.0, description="metres, final ICP inlier radius")
        icp_max_iterations: int = Field(40, ge=1, description="iterations per ICP run")
        icp_yaw_starts_deg: list[float] = Field(
            default_factory=lambda: [0.0, -12.0, 12.0, -25.0, 25.0],
            description="yaw offsets (degrees) of the ICP starts; the best fit wins",
        )
        viewpoint: Vec3 | None = Field(
            None,
            description="camera centre, world frame, metres (used when correct() is not given one); "
            "null: the ICP matches the cloud to the model only, not the visible model to the cloud",
        )
        reverse_weight: float = Field(
            1.0, ge=0.0, description="weight of the visible-model-to-cloud ICP term (0: cloud-to-model only)"
        )
        visible_max_incidence_deg: float = Field(
            70.0, gt=0.0, lt=90.0, description="model surface seen more obliquely is not expected in the cloud"
        )
        max_refine_shift: float = Field(
            0.03, gt=0.0, description="metres; an ICP result farther than this from the snapped pose is refused"
        )
        symmetry: Literal["nearest_raw", "canonical"] = Field(
            "nearest_raw",
            description="among symmetric equivalents keep the one nearest the raw rotation, or a canonical yaw",
        )

    def __init__(self, settings: Any = None, *, seed: int = 0) -> None:
        super().__init__(settings, seed=seed)
        self._surfaces: dict[str, ModelSurface] = {}

    # ------------------------------------------------------------ helpers
    def placements_for(self, part: PartModel) -> PlacementResult:
        """The part's placements (computed once per mesh and settings, then cached)."""
        s = self.settings
        return placement_result(part, min_margin=s.min_margin, angle_tol_deg=s.angle_tol_deg)

    def _surface(self, part: PartModel) -> ModelSurface:
        key = part.source_hash or str(id(part.mesh))
        if key not in self._surfaces:
            self._surfaces[key] = ModelSurface(part.mesh, seed=self.seed)
        return self._surfaces[key]

    def _table(self, table: TablePlane | None, cloud: np.ndarray | None) -> tuple[TablePlane, bool]:
        if table is not None and self.settings.table == "given":
            return table, False
        if cloud is None:
            raise UserError(
                "the table plane is neither given nor fittable: pass a TablePlane or a cloud that shows the table"
            )
        up = np.asarray(table.normal, dtype=float) if table is not None else np.array([0.0, 0.0, 1.0])
        return fit_table_plane(cloud, up=up, seed=self.seed), True

    # ------------------------------------------------------------ main
    def correct(
        self,
        T_world_part: np.ndarray,
        part: PartModel,
        table: TablePlane | None = None,
        cloud: np.ndarray | None = None,
        viewpoint: np.ndarray | None = None,
    ) -> Correction:
        """Correct a rough ``(4, 4)`` ``T_world_part`` of ``part`` resting on ``table``.

        ``cloud`` (world frame, metres) is the observed part segment, or a scene
        that also shows the table when the table is to be fitted; points within
        ``table_band`` of the table are ignored by the refinement. ``viewpoint``
        (``(3,)``, world frame, metres) is the camera centre; ``None`` uses the
        ``viewpoint`` setting.
        """
        s = self.settings
        t0 = time.perf_counter()
        T_raw_w = geometry.as_transform(T_world_part)
        table, fitted = self._table(table, cloud)
        T_wt = table_frame(table)
        T_raw = geometry.invert(T_wt) @ T_raw_w
        result = self.placements_for(part)
        if not result.placements:
            raise UserError(f"part {part.name!r} has no stable placement with margin >= {s.min_margin}")
        t_plan = time.perf_counter()

        # Lines 1-7 (line 4 fixed): nearest placement by geodesic distance to R_r.
        Rp = np.stack([p.T_table_part[:3, :3] for p in result.placements])
        d, psi = nearest_placement(T_raw[:3, :3], Rp, yaw_from=s.yaw_from)
        i = int(np.argmin(d))
        marginal = False
        if np.degrees(d[i]) > s.max_snap_deg and s.marginal_margin < s.min_margin:
            loose = placement_result(part, min_margin=s.marginal_margin, angle_tol_deg=s.angle_tol_deg)
            Rl = np.stack([p.T_table_part[:3, :3] for p in loose.placements])
            dl, psil = nearest_placement(T_raw[:3, :3], Rl, yaw_from=s.yaw_from)
            j = int(np.argmin(dl))
            if dl[j] < d[i]:
                result, Rp, d, psi, i, marginal = loose, Rl, dl, psil, j, True
        placement = result.placements[i]
        # Lines 8-10: keep the yaw, take roll and pitch from the placement, rest on the table.
        com = np.asarray(result.center_of_mass, dtype=float)
        T_snap = self._rest(result, Rp[i], float(psi[i]), T_raw, com)

        # Beyond the paper: planar ICP against the cloud, then the symmetric equivalent.
        icp_info: dict[str, Any] = {"applied": False}
        T_ref = T_snap
        if cloud is not None and s.refine:
            eye = viewpoint if viewpoint is not None else s.viewpoint
            T_ref, icp_info = self._refine(part, T_snap, T_raw_w, table, T_wt, cloud, placement, com, eye)
        order = len(placement.symmetry_yaws)
        T_fin, k = self._choose_equivalent(T_ref, T_raw, Rp[i], order, com)
        # Recompose exactly: R = Rz(psi) R_p and the lowest point at z = 0 (no drift from the ICP steps).
        M = T_fin[:3, :3] @ Rp[i].T
        psi_fin = float(np.arctan2(M[1, 0], M[0, 0]))
        T_fin = self._rest(result, Rp[i], psi_fin, T_fin, com)

        lowest = float((result.hull.vertices @ T_fin[:3, :3].T + T_fin[:3, 3])[:, 2].min())
        order_d = np.argsort(d)
        details: dict[str, Any] = {
            "distance_deg": float(np.degrees(d[i])),
            "marginal_rest": marginal,
            "second_distance_deg": float(np.degrees(d[order_d[1]])) if len(d) > 1 else None,
            "yaw_deg": float(np.degrees(psi_fin)),
            "probability": placement.probability,
            "margin": placement.margin,
            "symmetry_order": order,
            "equivalent_index": k,
            "table": {"height": table.height, "normal": table.normal.tolist(), "fitted": fitted},
            "lowest_point_mm": lowest * 1000.0,
            "snap_change": {
                "rotation_deg": float(np.degrees(geometry.rotation_distance(T_raw, T_snap))),
                "translation_mm": float(geometry.translation_distance(T_raw, T_snap) * 1000.0),
            },
            "icp": icp_info,
            "timing_ms": {
                "placements": (t_plan - t0) * 1000.0,
                "total": (time.perf_counter() - t0) * 1000.0,
            },
        }
        return Correction(T_world_part=T_wt @ T_fin, placement_id=placement.id, details=details)

    def _rest(
        self, result: PlacementResult, R_p: np.ndarray, psi: float, T_ref: np.ndarray, com: np.ndarray
    ) -> np.ndarray:
        """``Rz(psi) R_p`` resting on the table (lowest hull point at z = 0), pivot kept at T_ref's x, y."""
        R = _rz(np.array([psi]))[0] @ R_p
        if self.settings.pivot == "com":
            xy = (T_ref[:3, :3] @ com + T_ref[:3, 3])[:2] - (R @ com)[:2]
        else:
            xy = T_ref[:2, 3]
        z = -float((result.hull.vertices @ R.T)[:, 2].min())
        return geometry.from_rotation(R, [xy[0], xy[1], z])

    def _refine(
        self,
        part: PartModel,
        T_snap: np.ndarray,
        T_raw_w: np.ndarray,
        table: TablePlane,
        T_wt: np.ndarray,
        cloud: np.ndarray,
        placement: Any,
        com: np.ndarray,
        viewpoint: np.ndarray | None,
    ) -> tuple[np.ndarray, dict[str, Any]]:
        s = self.settings
        T_tw = geometry.invert(T_wt)
        pts = geometry.transform_points(T_tw, points_above(cloud, table, s.table_band))
        # Keep points near the part: within its bounding radius (plus slack) of the raw COM.
        radius = float(np.linalg.norm(part.mesh.extents)) * 0.75 + s.icp_max_correspondence
        com_t = geometry.transform_points(T_tw @ T_raw_w, com[None, :])[0]
        pts_t = pts[np.linalg.norm(pts - com_t, axis=1) < radius]
        if len(pts_t) < s.min_cloud_points:
            return T_snap, {"applied": False, "reason": f"{len(pts_t)} part points < {s.min_cloud_points}"}
        surface = self._surface(part)
        order = len(placement.symmetry_yaws)
        half_period = np.pi / order
        pivot = (T_snap[:3, :3] @ com + T_snap[:3, 3])[:2]
        kwargs = {
            "max_correspondence": s.icp_max_correspondence,
            "min_correspondence": s.icp_min_correspondence,
            "max_iterations": s.icp_max_iterations,
            "viewpoint": None if viewpoint is None else geometry.transform_points(T_tw, np.asarray(viewpoint)[None])[0],
            "reverse_weight": s.reverse_weight,
            "max_incidence": np.radians(s.visible_max_incidence_deg),
        }
        baseline = planar_icp(surface, T_snap, pts_t, **{**kwargs, "max_iterations": 0})
        best = None
        starts = [np.radians(a) for a in s.icp_yaw_starts_deg if abs(np.radians(a)) < half_period + 1e-9]
        for offset in starts or [0.0]:
            start = planar_transform(0.0, 0.0, offset, pivot) @ T_snap
            res = planar_icp(surface, start, pts_t, **kwargs)
            if best is None or res.cost < best[1].cost:
                best = (offset, res)
        assert best is not None
        offset, res = best
        shift = float(np.linalg.norm(res.T_table_part[:2, 3] - T_snap[:2, 3]))
        info: dict[str, Any] = {
            "points": len(pts_t),
            "viewpoint": viewpoint is not None,
            "coverage": res.coverage,
            "start_yaw_deg": float(np.degrees(offset)),
            "fitness": res.fitness,
            "rmse_mm": res.rmse * 1000.0,
            "cost_before": baseline.cost,
            "cost_after": res.cost,
            "iterations": res.iterations,
            "converged": res.converged,
            "xy_change_mm": shift * 1000.0,
            "yaw_change_deg": float(np.degrees(geometry.rotation_distance(res.T_table_part, T_snap))),
        }
        com_shift = float(
            np.linalg.norm(
                (res.T_table_part[:3, :3] @ com + res.T_table_part[:3, 3] - (T_snap[:3, :3] @ com + T_snap[:3, 3]))[:2]
            )
        )
        if com_shift > s.max_refine_shift or res.cost > baseline.cost:
            info.update(applied=False, reason="refinement moved too far or fitted worse; snapped pose kept")
            return T_snap, info
        info["applied"] = True
        return res.T_table_part, info

    def _choose_equivalent(
        self, T: np.ndarray, T_raw: np.ndarray, R_p: np.ndarray, order: int, com: np.ndarray
    ) -> tuple[np.ndarray, int]:
        """Among the ``order`` symmetric equivalents of ``T`` pick one (see ``Settings.symmetry``)."""
        if order <= 1:
            return T, 0
        pivot = (T[:3, :3] @ com + T[:3, 3])[:2]
        cands = [planar_transform(0.0, 0.0, 2.0 * np.pi * k / order, pivot) @ T for k in range(order)]
        if self.settings.symmetry == "nearest_raw":
            cost = [geometry.rotation_distance(C, T_raw) for C in cands]
        else:
            # canonical: relative yaw to the placement's canonical rotation in [-pi/m, pi/m)
            cost = []
            for C in cands:
                M = C[:3, :3] @ R_p.T
                cost.append(abs(float(np.arctan2(M[1, 0], M[0, 0]))))
        k = int(np.argmin(cost))
        return cands[k], k
