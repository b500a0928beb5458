"""Scoring a table-top segmentation against per-point truth labels (mOSD-style scenes).

Both labellings are ``(n,)`` integer arrays over the same points (one row per pixel of an organized
cloud, or per point):

* truth: ``IGNORE`` (-1) for points without a return (NaN), ``TABLE`` (0) for the supporting table and
  anything else that is no object, ``k > 0`` for object ``k``;
* ours: ``0`` (or any value <= 0) for points in no segment (table removed, too high, noise, no return),
  ``k > 0`` for segment ``k``.

Measures (points with truth ``IGNORE`` count nowhere):

* per-object IoU: ``|S n O| / |S u O|`` of the segment ``S`` that best overlaps object ``O`` (0 when no
  segment touches it); the median over the objects of a scene;
* table points left: truth-table points inside any segment (every segment is a candidate object, so a
  table point in any of them is table left in an object segment);
* merged: segments that cover more than one object; split: objects covered by more than one segment. A
  segment *covers* an object when it holds at least ``cover`` of the object's points (default 20 %), so
  a few stray boundary points do not count as a merge or a split.

:func:`mosd_truth` turns mOSD's label field into truth labels: 0 = no return, 1-9 = (parts of) the table,
10k..10k+9 = (parts of) object k. mOSD gives geometrically disjoint parts of one object (an occluded
object seen in two pieces) different labels, 10k and 10k+1, because a model-free segmentation cannot
know they belong together; ``whole_objects=False`` (the default) scores those parts as separate objects,
as the dataset intends, ``True`` as one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["IGNORE", "TABLE", "ObjectScore", "SceneScore", "mosd_truth", "score_segmentation"]

IGNORE = -1
"""Truth label of points that count nowhere (no sensor return)."""
TABLE = 0
"""Truth label of the table (and any other non-object point)."""


def mosd_truth(labels: np.ndarray, *, whole_objects: bool = False) -> np.ndarray:
    """mOSD ``label`` field -> truth labels (:data:`IGNORE`, :data:`TABLE`, objects ``> 0``).

    Object ids are the mOSD labels themselves (20, 30, 31, ...), or ``label // 10`` with ``whole_objects``.
    """
    lab = np.asarray(labels).astype(np.int64).reshape(-1)
    out = np.where(lab >= 10, lab // 10 if whole_objects else lab, TABLE)
    out[lab == 0] = IGNORE
    return out


@dataclass
class ObjectScore:
    """One truth object and the segment that matches it best."""

    label: int
    points: int
    """Points of the object with a return."""
    iou: float
    segment: int
    """Best-matching segment (its label in ours), or 0 when no segment touches the object."""
    covered_by: int
    """Segments holding at least ``cover`` of the object's points (> 1: split)."""


@dataclass
class SceneScore:
    """A segmentation scored against the truth of one scene."""

    objects: list[ObjectScore] = field(default_factory=list)
    segments: int = 0
    """Segments in ours."""
    table_points_left: int = 0
    """Truth-table points inside segments."""
    table_segments: int = 0
    """Segments holding any truth-table point."""
    merged: int = 0
    """Segments covering more than one object."""
    split: int = 0
    """Objects covered by more than one segment."""
    false_segments: int = 0
    """Segments covering no object (table patches, clutter fragments)."""

    @property
    def median_iou(self) -> float:
        """Median per-object IoU (``nan`` when the scene has no object)."""
        return float(np.median([o.iou for o in self.objects])) if self.objects else float("nan")

    @property
    def ious(self) -> list[float]:
        """Per-object IoU in truth-label order."""
        return [o.iou for o in self.objects]


def score_segmentation(truth: np.ndarray, ours: np.ndarray, *, cover: float = 0.2) -> SceneScore:
    """Score ``ours`` (segment ids, ``<= 0``: none) against ``truth`` (see the module docstring).

    ``cover`` (0..1] is the share of an object's points a segment must hold to count as covering it.
    """
    t = np.asarray(truth).astype(np.int64).reshape(-1)
    s = np.asarray(ours).astype(np.int64).reshape(-1)
    if t.shape != s.shape:
        raise ValueError(f"truth and ours must label the same points: {t.shape} vs {s.shape}")
    if not 0.0 < cover <= 1.0:
        raise ValueError(f"cover must be in (0, 1], got {cover}")
    keep = t != IGNORE
    t, s = t[keep], np.where(s[keep] > 0, s[keep], 0)
    obj_ids = np.unique(t[t > 0])
    seg_ids = np.unique(s[s > 0])
    # Contingency table: rows = table + objects, columns = "no segment" + segments.
    ti = np.searchsorted(np.concatenate([[TABLE], obj_ids]), t)
    si = np.searchsorted(np.concatenate([[0], seg_ids]), s)
    nr, nc = len(obj_ids) + 1, len(seg_ids) + 1
    table = np.bincount(ti * nc + si, minlength=nr * nc).reshape(nr, nc)
    inter = table[1:, 1:]  # objects x segments
    obj_n = table[1:].sum(axis=1)
    seg_n = table[:, 1:].sum(axis=0)
    covers = inter >= cover * obj_n[:, None]
    out = SceneScore(segments=len(seg_ids))
    for i, lab in enumerate(obj_ids):
        union = obj_n[i] + seg_n - inter[i]
        iou = np.where(union > 0, inter[i] / np.maximum(union, 1), 0.0)
        j = int(np.argmax(iou)) if len(iou) else -1
        best = float(iou[j]) if j >= 0 and inter[i, j] > 0 else 0.0
        out.objects.append(
            ObjectScore(
                label=int(lab),
                points=int(obj_n[i]),
                iou=best,
                segment=int(seg_ids[j]) if best > 0 else 0,
                covered_by=int(covers[i].sum()),
            )
        )
    out.table_points_left = int(table[0, 1:].sum())
    out.table_segments = int(np.count_nonzero(table[0, 1:]))
    per_seg = covers.sum(axis=0)
    out.merged = int(np.count_nonzero(per_seg > 1))
    out.split = int(np.count_nonzero(covers.sum(axis=1) > 1))
    out.false_segments = int(np.count_nonzero(per_seg == 0))
    return out
