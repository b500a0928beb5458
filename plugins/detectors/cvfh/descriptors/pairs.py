"""Darboux-frame pair features (f1, f2, f3, f4) of PFH/VFH, vectorised over many pairs.

The features follow ``pcl::computePairFeatures`` (PCL 1.13): for a source point ``p1`` with normal ``n1`` and a
target ``p2`` with ``n2``, the pair is first ordered so that the point whose normal makes the smaller angle with the
connecting line is the source; then ``u = n_s``, ``v = (p_t - p_s) x u / |.|``, ``w = u x v`` and

- ``f1 = atan2(w . n_t, u . n_t)`` in ``[-pi, pi]`` (radians),
- ``f2 = v . n_t`` in ``[-1, 1]``,
- ``f3 = u . (p_t - p_s) / |p_t - p_s|`` in ``[-1, 1]``,
- ``f4 = |p2 - p1|`` in metres.

As in PCL the source normal is used as given: VFH feeds a mean normal that need not be unit length, which scales
``f3`` and the ``u`` axis, and this module does not renormalise it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray


@dataclass(frozen=True)
class PairFeatures:
    """Pair features of ``n`` pairs.

    Attributes:
        f1: ``(n,)`` angle of the target normal in the Darboux (u, w) plane, radians in ``[-pi, pi]``.
        f2: ``(n,)`` cosine of the target normal with the v axis.
        f3: ``(n,)`` cosine of the source normal with the connecting line.
        f4: ``(n,)`` distance between the two points, metres.
        valid: ``(n,)`` bool; False where PCL rejects the pair (coincident points, or a connecting line parallel
            to the source normal). PCL leaves such pairs out of every histogram.
    """

    f1: NDArray[np.float64]
    f2: NDArray[np.float64]
    f3: NDArray[np.float64]
    f4: NDArray[np.float64]
    valid: NDArray[np.bool_]


def pair_features(p1: ArrayLike, n1: ArrayLike, p2: ArrayLike, n2: ArrayLike) -> PairFeatures:
    """Compute PCL's pair features for pairs ``(p1[i], n1[i]) -> (p2[i], n2[i])``.

    Args:
        p1: ``(3,)`` or ``(n, 3)`` source points, metres (any common frame).
        n1: ``(3,)`` or ``(n, 3)`` source normals (used as given, see module docstring).
        p2: ``(3,)`` or ``(n, 3)`` target points, metres.
        n2: ``(3,)`` or ``(n, 3)`` target normals.

    Returns:
        The features of the broadcast pairs; invalid pairs have all four features set to 0, as PCL does.
    """
    arrays = (np.atleast_2d(np.asarray(a, dtype=np.float64)) for a in (p1, n1, p2, n2))
    p1a, n1a, p2a, n2a = np.broadcast_arrays(*arrays)
    d = p2a - p1a
    f4 = np.linalg.norm(d, axis=1)
    valid = f4 > 0.0
    inv = np.divide(1.0, f4, out=np.zeros_like(f4), where=valid)
    angle1 = np.einsum("ij,ij->i", n1a, d) * inv
    angle2 = np.einsum("ij,ij->i", n2a, d) * inv
    # PCL swaps when acos|a1| > acos|a2|, i.e. |a1| < |a2|: the source is the point whose normal is better aligned
    # with the connecting line, which makes the features independent of the order the pair is given in.
    swap = (np.abs(angle1) < np.abs(angle2))[:, None]
    u = np.where(swap, n2a, n1a)
    target_n = np.where(swap, n1a, n2a)
    d = np.where(swap, -d, d)
    f3 = np.where(swap[:, 0], -angle2, angle1)

    v = np.cross(d, u)
    v_norm = np.linalg.norm(v, axis=1)
    valid &= v_norm > 0.0
    v = v * np.divide(1.0, v_norm, out=np.zeros_like(v_norm), where=valid)[:, None]
    w = np.cross(u, v)
    f2 = np.einsum("ij,ij->i", v, target_n)
    f1 = np.arctan2(np.einsum("ij,ij->i", w, target_n), np.einsum("ij,ij->i", u, target_n))
    zero = ~valid
    for f in (f1, f2, f3, f4):
        f[zero] = 0.0
    return PairFeatures(f1=f1, f2=f2, f3=f3, f4=f4, valid=valid)
