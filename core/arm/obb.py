"""Oriented bounding boxes, vectorised with numpy: overlap (separating-axis test) and a lower bound of their gap.

A box is a frame (centre and axes, world, metres) and its ``(3,)`` half extents.
"""

from __future__ import annotations

import numpy as np

__all__ = ["obb_gap", "obb_overlap"]


def obb_overlap(
    cA: np.ndarray, RA: np.ndarray, hA: np.ndarray, cB: np.ndarray, RB: np.ndarray, hB: np.ndarray
) -> np.ndarray:
    """Separating-axis test of oriented boxes, vectorised: True where boxes ``A[k]`` and ``B[k]`` overlap.

    ``c*`` are ``(m, 3)`` centres, ``R*`` ``(m, 3, 3)`` rotations (columns: box axes in
    the world), ``h*`` ``(m, 3)`` half extents. Touching boxes count as overlapping.
    """
    R = np.einsum("mji,mjk->mik", RA, RB)  # B's axes in A's frame
    t = np.einsum("mji,mj->mi", RA, cB - cA)  # B's centre in A's frame
    aR = np.abs(R) + 1e-9
    sep = np.any(np.abs(t) > hA + np.einsum("mij,mj->mi", aR, hB), axis=1)
    tb = np.einsum("mi,mij->mj", t, R)
    sep |= np.any(np.abs(tb) > np.einsum("mi,mij->mj", hA, aR) + hB, axis=1)
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for j in range(3):
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            lhs = np.abs(t[:, i2] * R[:, i1, j] - t[:, i1] * R[:, i2, j])
            rhs = (
                hA[:, i1] * aR[:, i2, j]
                + hA[:, i2] * aR[:, i1, j]
                + hB[:, j1] * aR[:, i, j2]
                + hB[:, j2] * aR[:, i, j1]
            )
            sep |= lhs > rhs
    return ~sep


def obb_gap(Wa: np.ndarray, half_a: np.ndarray, Wb: np.ndarray, half_b: np.ndarray) -> np.ndarray:
    """``(n, A, B)`` separation (metres; negative: none) of OBBs A from OBBs B along B's face normals.

    ``Wa`` ``(n, A, 4, 4)`` and ``Wb`` ``(n, B, 4, 4)`` are the OBB frames in the world,
    ``half_*`` their half extents. A plane through a face of B with all of A
    outside it separates them, so the largest such gap bounds their distance from below.
    """
    signs = np.array(np.meshgrid([-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0], indexing="ij")).reshape(3, -1).T  # (8, 3)
    corners = Wa[:, :, None, :3, 3] + np.einsum("naij,aj,cj->naci", Wa[..., :3, :3], half_a, signs)  # (n, A, 8, 3)
    rel = corners[:, :, None] - Wb[:, None, :, None, :3, 3]  # (n, A, B, 8, 3)
    s = np.einsum("nabcj,nbjk->nabck", rel, Wb[..., :3, :3])  # along B's axes
    h = half_b[None, None, :, :]
    return np.max(np.maximum(s.min(axis=3) - h, -s.max(axis=3) - h), axis=3)
