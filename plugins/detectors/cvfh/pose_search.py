"""The ``cvfh_icp`` detector's pose search on one cluster: hypotheses, verification rounds, twin passes.

All poses are ``T_world_part`` (world frame, metres, z up). The detector
(:class:`~asmteach.plugins.detectors.cvfh.detector.CvfhIcpDetector`) pre-scores the hypotheses and calls,
in order:

* :func:`view_hypotheses`: the nearest database views and their CRH roll peaks turned into poses;
* :func:`verify_rounds`: coarse ICP, fine ICP and verification of the best pre-scored ones, in rounds of
  ``icp_candidates`` until one verifies;
* :func:`hull_twin_pass`: the verified pose turned by each hull twin, the ray evidence choosing;
* :func:`near_twin_pass`: the pose turned by each near twin and nudge, and the distinct rivals that
  score as well, if any (the view cannot tell them apart);
* :func:`rest_pass`: what the table says of poses the view cannot tell apart (the part lies at rest on it);

and then :mod:`~asmteach.plugins.detectors.cvfh.pinning` judges how well the seen points pin the winner down.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from asmteach.core.models import TablePlane
from asmteach.core.perception.registration import (
    ModelCloud,
    RefineSettings,
    Verdict,
    icp_refine,
    verify,
)
from asmteach.core.perception.viewpoint import StageClock
from asmteach.core.symmetry.near import NearSymmetry
from asmteach.plugins.detectors.cvfh.prescore import SampleIndex, near_shares, support_gap
from asmteach.plugins.detectors.cvfh.resting import disagreement, rests_near, slide_on_table, snap_to_rest
from asmteach.plugins.detectors.cvfh.settings import CvfhSettings
from asmteach.plugins.detectors.cvfh.views import CloudDescription, ViewDatabase

__all__ = [
    "ClusterJob",
    "Prepared",
    "hull_twin_pass",
    "is_distinct",
    "near_twin_pass",
    "poses_apart",
    "rest_pass",
    "settle",
    "verify_at_rest",
    "verify_rounds",
    "view_hypotheses",
]


@dataclass
class Prepared:
    """What the detector builds once per part (see :meth:`CvfhIcpDetector.prepare`)."""

    model: ModelCloud
    db: ViewDatabase
    diameter: float
    built_now: bool
    build_ms: float
    rests: np.ndarray
    """(k, 4, 4) stable rests on z = 0 (see :func:`stable_rests`)."""
    twins: list[np.ndarray]
    """Part-frame rotations keeping the convex hull but not the part (see :func:`hull_twins`)."""
    near: list[np.ndarray]
    """Part-frame rotations keeping the part nearly (see :func:`near_twins`)."""
    own: list[np.ndarray]
    """The part's own symmetries (poses that differ by one are the same pose)."""
    samples: SampleIndex
    """The model's surface samples indexed for the pre-score's distance tests."""
    thin: bool = False
    """The part is thin enough to lie mostly below the table-removal height (``thin_height``)."""
    free: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """(m, 3) part-frame axes of revolution (see :func:`~asmteach.plugins.detectors.cvfh.pinning.free_axes`)."""
    same: NearSymmetry | None = None
    """Tells two poses that put the surface in the same place (``same_surface``; ``None``: listed symmetries only)."""
    every_rest: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 4)))
    """(k, 4, 4) every pose the part can rest in on z = 0, however unlikely (see :func:`every_rest`): the table
    decides between poses only when none is missing."""


@dataclass
class ClusterJob:
    """One observed cluster and what its hypotheses are checked against (world frame, metres)."""

    cluster: np.ndarray
    context: np.ndarray
    icp_in: np.ndarray
    icp_sub: np.ndarray
    table: TablePlane
    eye: np.ndarray
    judged: list[np.ndarray] = field(default_factory=list)
    """Poses the hull-twin pass verified and judged by the ray evidence (the near-twin pass leaves them alone)."""
    icp_passes: int = 0
    """Open3D ICP runs so far (a coarse + fine refinement is two): the detection's main cost."""

    def icp(
        self, points: np.ndarray, model: ModelCloud, T_world_part: np.ndarray, s: RefineSettings, **passes: bool
    ) -> np.ndarray:
        """:func:`icp_refine` of ``points`` (world, metres), counted in :attr:`icp_passes`."""
        self.icp_passes += passes.get("coarse", True) + passes.get("fine", True)
        eye = self.eye if s.visible_icp else None
        return icp_refine(points, model, T_world_part, s, viewpoint=eye, **passes)

    def verify(self, T_world_part: np.ndarray, model: ModelCloud, s: RefineSettings) -> Verdict:
        """:func:`verify` of a pose against this cluster and its context, seen from :attr:`eye`, on :attr:`table`."""
        return verify(T_world_part, self.cluster, self.context, self.eye, model, s, self.table)


def view_hypotheses(
    desc: CloudDescription, db: ViewDatabase, T_world_vcam: np.ndarray, s: CvfhSettings
) -> list[tuple[int, np.ndarray, float]]:
    """``(view, T_world_part, roll)`` from the nearest views and their CRH roll peaks."""
    from asmteach.plugins.detectors.cvfh.descriptors import crh_roll_candidates

    # L1 distance between every cluster region and every view region; a view scores its best pair.
    d = np.abs(desc.hists[:, None, :] - db.hists[None, :, :]).sum(axis=2).min(axis=0)
    view_best = np.full(len(db.T_acam_part), np.inf)
    np.minimum.at(view_best, db.region_view, d)
    order = [int(i) for i in np.argsort(view_best) if np.isfinite(view_best[i])][: s.nn_views]
    out: list[tuple[int, np.ndarray, float]] = []
    for i in order:
        if desc.crh is None or not np.any(db.crh[i]):
            # A face seen head-on has no roll histogram: try rolls all round instead.
            rolls = list(np.linspace(-np.pi, np.pi, s.blind_rolls, endpoint=False))
        else:
            # The roll that turns the view into the cluster (view a -> cluster b).
            rolls = crh_roll_candidates(db.crh[i], desc.crh, max_peaks=s.max_rolls)
        for roll in rolls:
            # Cluster ~ Rz(roll) view, both centroids on +z: rotate about the view centroid, then move it.
            # (Rz written out: scipy's Rotation per roll was 4 % of detect.)
            c, s_ = np.cos(roll), np.sin(roll)
            T_align = np.eye(4)
            T_align[:3, :3] = [[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]]
            T_align[:3, 3] = desc.centroid - T_align[:3, :3] @ db.centroids[i]
            out.append((i, T_world_vcam @ T_align @ db.T_acam_part[i], float(roll)))
    return out


def verify_rounds(
    scored: list[tuple[int, np.ndarray, float]],
    job: ClusterJob,
    prep: Prepared,
    clock: StageClock,
    s: CvfhSettings,
    max_rounds: int | None = None,
) -> tuple[Verdict | None, Verdict | None, dict]:
    """Refine and verify pre-scored hypotheses in rounds until one verifies: ``(best, closest miss, info)``.

    At most ``max_rounds`` rounds (default: the ``max_rounds`` setting).
    """
    max_rounds = s.max_rounds if max_rounds is None else max_rounds
    best: Verdict | None = None
    closest: Verdict | None = None
    info: dict = {}
    rounds = 0
    # Rounds of icp_candidates hypotheses, best pre-scored first; later rounds only when nothing verified.
    for first in range(0, min(len(scored), max_rounds * s.icp_candidates), s.icp_candidates):
        rounds += 1
        # Coarse ICP on a subsample for every candidate, fine ICP and verification for the best few.
        batch = scored[first : first + s.icp_candidates]
        Ts = [job.icp(job.icp_sub, prep.model, T0, s.refine, fine=False) for _, T0, _ in batch]
        coarse = []
        shares = near_shares(Ts, job.icp_sub, prep.model, s.refine.inlier_distance, prep.samples)
        for (view, T0, roll), T, share in zip(batch, Ts, shares, strict=True):
            score = float(share)
            if abs(support_gap(T, prep.model, job.table)) > 2.0 * s.refine.support_tolerance:
                score -= 1.0  # resting inside the table or floating: last in line
            coarse.append((score, view, T, roll, T0))
        coarse.sort(key=lambda c: -c[0])
        clock.lap("icp")
        accepted = 0
        for _, view, T1, roll, T0 in coarse[: s.verify_candidates]:
            if accepted >= 2:
                break  # two verified poses are enough to pick the better of a near-symmetric pair
            T = job.icp(job.icp_in, prep.model, T1, s.refine, coarse=False)
            clock.lap("icp")
            v = verify_at_rest(T, job, prep, s)
            if not v.accepted:
                # the hypothesis itself at its rest, slid along the table: ICP drifts a thin part off a resting
                # hypothesis (ff_lower_leg3 scenes 2 and 4: fitness 0.89-0.90 after ICP)
                at_rest = _at_nearest_rest(T0, job, prep, s)
                if at_rest is not None:
                    alt = job.verify(at_rest, prep.model, s.refine)
                    v = alt if alt.accepted else v
            clock.lap("verify")
            accepted += v.accepted
            if v.accepted and (best is None or v.score > best.score):
                best = v
                info = {"view": int(view), "roll_deg": round(float(np.degrees(roll)), 2)}
            if closest is None or v.score > closest.score:
                closest = v
        if best is not None:
            break
    info["rounds"] = rounds
    return best, closest, info


def verify_at_rest(T_world_part: np.ndarray, job: ClusterJob, prep: Prepared, s: CvfhSettings) -> Verdict:
    """:func:`verify` the refined pose; when rejected and within ``rest_snap_deg`` of a stable rest, verify it
    again snapped onto that rest (:func:`snap_to_rest`), and keep the snapped verdict if accepted.

    The paper's premise, a part lying at rest on the table, as a constraint after ICP: the points below
    ``segment.min_height`` are cut off as table, and a part that loses much of its height there (a U bracket
    15 mm tall turned over, its legs cut off half-way) leaves ICP free to tilt it. The snapped pose faces
    the same checks; rivals in the twin passes get the same chance.
    """
    v = job.verify(T_world_part, prep.model, s.refine)
    if v.accepted or s.rest_snap_deg <= 0.0 or not len(prep.rests):
        return v
    T, deg = snap_to_rest(T_world_part, prep.rests, prep.model, job.table)
    if deg > s.rest_snap_deg:
        return v
    snapped = job.verify(T, prep.model, s.refine)
    return snapped if snapped.accepted else v


def hull_twin_pass(
    best: Verdict, job: ClusterJob, prep: Prepared, clock: StageClock, s: CvfhSettings
) -> tuple[Verdict, int, list[dict]]:
    """Try ``best`` turned by each hull twin; keep the pose the disagreement evidence favours.

    Returns the chosen verdict, the number of twins that verified, and the
    twins the view cannot tell from it (pose, scores, evidence), for the report.
    """
    verified, undecided = 0, []
    for S in prep.twins:
        T = job.icp(job.icp_in, prep.model, best.T_world_part @ S, s.refine, coarse=False)
        v = verify_at_rest(T, job, prep, s)
        clock.lap("verify")
        if not v.accepted:
            continue
        verified += 1
        job.judged += [T, best.T_world_part]
        if not is_distinct(T, [best.T_world_part], prep.own, s, same=prep.same):
            continue  # ICP brought the twin back onto the pose (or a symmetric equivalent): nothing to choose
        ev = disagreement(best.T_world_part, T, job.cluster, job.eye, prep.model, s.twin_fit, s.twin_off)
        verdict = ev.verdict(s.twin_min_points, s.twin_ratio)
        if verdict == "b" or (verdict == "ambiguous" and v.score > best.score):
            best, v = v, best
        if verdict == "ambiguous":
            undecided.append(v)
    # the evidence is stated against the final choice
    ambiguous = []
    for v in undecided:
        ev = disagreement(best.T_world_part, v.T_world_part, job.cluster, job.eye, prep.model, s.twin_fit, s.twin_off)
        ambiguous.append(
            {
                "T_world_part": v.T_world_part.tolist(),
                "fitness": round(v.fitness, 4),
                "violation": round(v.violation, 4),
                "points_against": [ev.against_a, ev.against_b],
            }
        )
    clock.lap("verify")
    return best, verified, ambiguous


def near_twin_pass(
    best: Verdict, job: ClusterJob, prep: Prepared, clock: StageClock, s: CvfhSettings
) -> tuple[Verdict, list[Verdict]]:
    """Try ``best`` turned by each near twin: ``(the best-scoring verified pose, the distinct rivals)``.

    A rival is a verified pose, distinct from the winner (beyond the part's
    own symmetries), scoring within ``ambiguity_margin`` of it, that the
    disagreement evidence (``near_fit``, ``near_off``) does not rule out;
    the list is empty when the view tells every turned pose from the winner.
    """
    found = [best]
    # Hull twins the hull pass verified were judged there (found with details["ambiguous"] when the view
    # cannot tell); the ones it could not verify (its ICP is fine-only) get a full ICP here.
    judged = list(job.judged)
    screen = s.refine.model_copy(update={"icp_iterations": s.near_screen_iterations})
    screen = screen if s.near_screen_iterations > 0 else None
    for S in prep.near:
        T0 = best.T_world_part @ S
        tried = [v.T_world_part for v in found] + judged
        at_rest = _at_nearest_rest(T0, job, prep, s)
        if at_rest is not None and is_distinct(at_rest, tried, prep.own, s, same=prep.same):
            # the turned pose also at its rest, slid along the table: ICP, free in six, drifts a thin part off the
            # pose the view and the table agree on (ff_lower_leg3 scene 0: the truth scores 0.970 where it is,
            # and ICP from it drifts 16 deg and fails; the pose found, turned over, scored 0.958)
            v = job.verify(at_rest, prep.model, s.refine)
            clock.lap("verify")
            if v.accepted:
                found.append(v)
                tried.append(at_rest)
        # 3 in 4 turned poses fall back onto a pose already tried (the found one): a full ICP from them costs
        # 4-6x a short coarse one, which already brings them within a few mm / deg of it.
        if screen is not None and not is_distinct(
            job.icp(job.icp_sub, prep.model, T0, screen, fine=False), tried, prep.own, s, 0.5
        ):
            clock.lap("icp")
            continue
        T = job.icp(job.icp_in, prep.model, T0, s.refine)
        clock.lap("icp")
        if not is_distinct(T, tried, prep.own, s, same=prep.same):
            continue  # ICP pulled it back onto a pose already tried (or one with the same surface)
        v = verify_at_rest(T, job, prep, s)
        clock.lap("verify")
        if v.accepted:
            found.append(v)
    found.sort(key=lambda v: -v.score)
    return found[0], _rivals(found[0], found[1:], job, prep, s)


def _rivals(winner: Verdict, others: list[Verdict], job: ClusterJob, prep: Prepared, s: CvfhSettings) -> list[Verdict]:
    """The verified ``others`` the view cannot tell from ``winner``: distinct from it, scoring within
    ``ambiguity_margin`` of it and not ruled out by the disagreement evidence (``near_fit``, ``near_off``)."""
    out = []
    for v in others:
        if winner.score - v.score > s.ambiguity_margin or not is_distinct(
            v.T_world_part, [winner.T_world_part], prep.own, s, same=prep.same
        ):
            continue
        ev = disagreement(winner.T_world_part, v.T_world_part, job.cluster, job.eye, prep.model, s.near_fit, s.near_off)
        if ev.verdict(s.twin_min_points, s.twin_ratio) != "a":
            out.append(v)
    return out


def rest_pass(
    poses: list[np.ndarray], job: ClusterJob, prep: Prepared, clock: StageClock, s: CvfhSettings
) -> Verdict | None:
    """The one pose at rest on the table among ``poses`` the view cannot tell apart, if the table decides.

    The paper's premise: a part lies at rest on the table (the corrector snaps every detection onto a stable
    placement). A turn the camera cannot see is often one the table forbids: a D peg lying on its flat, seen from
    above, is a cylinder to the camera, and its roll about its axis (the flat's edges are under the round side,
    out of any view from above) sinks one edge into the table and lifts the other. Each of ``poses`` is put at
    every rest within ``rest_rivals_deg`` of it, its yaw and its place on the table kept
    (:func:`~asmteach.plugins.detectors.cvfh.resting.rests_near`), moved on the table to fit the view
    (:func:`~asmteach.plugins.detectors.cvfh.resting.slide_on_table`) and verified. The rests are
    :attr:`Prepared.every_rest`, every hull facet the centre of mass lies over, however unlikely: with only the
    likely rests, a keyed peg lying on a facet of its round side, key sideways, was put on the likeliest rest near
    it, key down, which the view could not refute. The answer is the verified resting pose when there is one and only
    one (up to the part's symmetries and same surface). ``None`` when one of ``poses`` has no verified resting pose
    near it (the truth may be that one, at a rest verification refuses) or two distinct resting poses verify (the
    view could not tell its poses apart; the table does not tell these). World frame, metres.
    """
    if s.rest_rivals_deg <= 0.0 or not len(prep.every_rest):
        return None
    resting: list[Verdict] = []
    tried: list[tuple[np.ndarray, bool]] = []  # resting poses verified so far, and whether each was accepted
    for T in poses:
        rests_ok = False
        for Tr, _ in rests_near(T, prep.every_rest, prep.model, job.table, s.rest_rivals_deg):
            seen = [ok for U, ok in tried if not is_distinct(Tr, [U], prep.own, s, same=prep.same)]
            if seen:
                rests_ok |= any(seen)
                continue
            Tr = slide_on_table(Tr, job.icp_in, prep.model, job.table, s.refine.inlier_distance)
            v = job.verify(Tr, prep.model, s.refine)
            clock.lap("verify")
            tried.append((Tr, v.accepted))
            if not v.accepted:
                continue
            rests_ok = True
            if resting:
                # two distinct resting poses the view accepts: the table does not decide between them, and the view
                # already could not (a keyed peg on its round side has a rest every 5.6 deg, dozens near the rivals;
                # picking the better-scoring of two, rod_1 seen as a CAD STL was found 90 deg off)
                return None
            resting.append(v)
        if not rests_ok:
            # a pose the view allows with no resting pose the view accepts near it: the truth may be that pose,
            # at a rest verification refuses (a rod with four stacked frames: its fitness 0.93-0.94 < 0.95), so
            # the rest that verified is no answer (rod_1 seen as a CAD STL: found 90 deg off)
            return None
    return resting[0] if resting else None


def _at_nearest_rest(T: np.ndarray, job: ClusterJob, prep: Prepared, s: CvfhSettings) -> np.ndarray | None:
    """``T`` at its nearest rest within ``rest_snap_deg``, slid along the table to fit the view; ``None`` when no
    rest is that near (or the table's say is off: ``rest_rivals_deg`` or ``rest_snap_deg`` 0)."""
    if s.rest_rivals_deg <= 0.0 or s.rest_snap_deg <= 0.0 or not len(prep.every_rest):
        return None
    near = rests_near(T, prep.every_rest, prep.model, job.table, s.rest_snap_deg)
    return slide_on_table(near[0][0], job.icp_in, prep.model, job.table, s.refine.inlier_distance) if near else None


def settle(best: Verdict, job: ClusterJob, prep: Prepared, clock: StageClock, s: CvfhSettings) -> Verdict | None:
    """``best`` put at its nearest rest, when one is within ``rest_snap_deg``, slid along the table to fit the view
    and verified: the resting pose if it is accepted and scores within ``ambiguity_margin`` of ``best``, else
    ``None`` (no rest near: a part leaning on something; or the view refutes the rest).

    The paper's premise, a part at rest on the table, as the corrector applies it, here on a pose the view pins
    down: ICP leaves a pose tilted a few degrees where the seen surface is smooth (a filleted block, the duck),
    and the table, not the view, knows its tilt. World frame, metres.
    """
    T = _at_nearest_rest(best.T_world_part, job, prep, s)
    if T is None:
        return None
    v = job.verify(T, prep.model, s.refine)
    clock.lap("verify")
    return v if v.accepted and v.score >= best.score - s.ambiguity_margin else None


def poses_apart(A: np.ndarray, B: np.ndarray, own: list[np.ndarray]) -> tuple[float, float]:
    """``(mm, deg)`` between two poses, the nearest of ``B``'s symmetric equivalents ``B @ S``."""
    BS = np.einsum("ij,sjk->sik", B, np.asarray(own).reshape(-1, 4, 4))
    mm = 1000.0 * np.linalg.norm(BS[:, :3, 3] - A[:3, 3], axis=1)
    cos = (np.einsum("ij,sij->s", A[:3, :3], BS[:, :3, :3]) - 1.0) / 2.0
    deg = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    i = int(np.argmin(mm + deg))
    return float(mm[i]), float(deg[i])


def is_distinct(
    T: np.ndarray,
    others: list[np.ndarray],
    own: list[np.ndarray],
    s: CvfhSettings,
    scale: float = 1.0,
    same: NearSymmetry | None = None,
) -> bool:
    """Whether ``T`` is farther than ``scale * distinct_mm`` or turned more than ``scale * distinct_deg`` from
    every other (up to the part's listed symmetries ``own``), and, with ``same``, does not put the surface
    where another puts it (:meth:`NearSymmetry.same`, a symmetry the list misses)."""
    for O in others:
        mm, deg = poses_apart(T, O, own)
        if mm <= scale * s.distinct_mm and deg <= scale * s.distinct_deg:
            return False
    return same is None or not any(same.same(T, O, s.distinct_mm) for O in others)
