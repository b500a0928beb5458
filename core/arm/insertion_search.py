"""Where a guarded insertion shifts its line next: along the contact's lateral push, halving at a crossing,
the other sense when one leads nowhere.

At each resistance the guarded insertion (:mod:`asmteach.core.arm.insertion`) reads which side of the part
the contact acts on. Away from it is the way in for a peg on a hole's rim, but the wrong way for a cap on a
post or a bore on a pin: there the part rests on the other part's top on the side nearest the axis, so the
"away" shifts walked the cap off the post 0.4 mm per try (gen_cap_on_post_s0_1 seed 9: 2.4 mm out, jammed).
And one fixed step (0.4 mm) jumps back and forth over a play narrower than itself (that cap's 0.26 mm).

:class:`PushSearch` follows the push (each reading's own direction: real contact readings are noisy, tens of
degrees), halves its step each time the push turns back (the part crossed the axis of what it goes into), and
when the shifts reach the search radius without a crossing, goes back to where the search began and follows
the push the other way; with no push read, the offsets follow a :func:`spiral`. Metres, world frame (offsets
perpendicular to the insertion line).
"""

from __future__ import annotations

import numpy as np

__all__ = ["PushSearch", "perpendicular", "spiral"]


class PushSearch:
    """Sideways offsets of the insertion line to try, from the lateral push read at each resistance.

    ``step`` (metres): the first shift; ``radius``: no shift farther than this from the planned line (one
    sense reaching it turns the search to the other); ``min_step``: the step is never halved below this.
    """

    def __init__(self, step: float, radius: float, min_step: float = 0.00005) -> None:
        self.step, self.radius, self.min_step = step, radius, min_step
        self.h = step
        self.sense = 1.0
        self.origin: np.ndarray | None = None
        self.first: np.ndarray | None = None  # the push read where the search began
        self.prev: np.ndarray | None = None

    def next(self, offset: np.ndarray, away: np.ndarray | None) -> np.ndarray | None:
        """The next offset to try after a resistance at ``offset`` whose lateral push was ``away`` (a unit
        vector, or None when unread); None when this search has nothing more to try."""
        if away is None:
            return None
        if self.origin is None:
            self.origin, self.first = np.asarray(offset, dtype=float).copy(), away
        if self.prev is not None and float(np.dot(away, self.prev)) < 0.0:
            self.h = max(0.5 * self.h, self.min_step)  # crossed: the way in lies between the last two shifts
        self.prev = away
        new = offset + self.sense * self.h * away
        if np.linalg.norm(new) <= self.radius:
            return new
        if self.sense < 0.0 or self.first is None:
            return None
        # this sense led to the edge of the search without a crossing: the push points away from the way in
        self.sense, self.h, self.prev = -1.0, self.step, None
        return self.origin - self.step * self.first


def perpendicular(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to ``d`` and to each other."""
    a = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(d, a)
    u /= np.linalg.norm(u)
    return u, np.cross(d, u)


def spiral(k: int, pitch: float, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The ``k``-th point (k >= 1) of an Archimedean spiral with ``pitch`` metres between points and turns."""
    theta = np.sqrt(4.0 * np.pi * k)  # equal arc length between points
    r = pitch * theta / (2.0 * np.pi)
    return r * (np.cos(theta) * u + np.sin(theta) * w)
