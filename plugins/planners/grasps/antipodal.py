"""Friction cones, the antipodal test and a wrench-space force-closure check.

Two contacts with Coulomb friction ``mu`` form a force-closure grasp exactly
when the line through them lies inside both friction cones (Nguyen 1988): the
antipodal test, vectorised here for thousands of pairs. Its half-angle is
``atan(mu)``: 16.7 deg for the default ``mu = 0.3``.

:func:`wrench_space_quality` is the slower, general check used to verify it:
the grasp wrench space of soft-finger contacts (a linearised friction cone plus
a torsional moment about the normal, since flat pads resist twisting) and its
Ferrari-Canny quality, the radius of the largest ball about the origin inside
the convex hull of the primitive wrenches; positive means force closure.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

__all__ = ["antipodal_angles", "antipodal_mask", "friction_half_angle", "wrench_space_quality"]


def friction_half_angle(mu: float) -> float:
    """Half-angle (radians) of the Coulomb friction cone of coefficient ``mu``."""
    return float(np.arctan(mu))


def antipodal_angles(p0: np.ndarray, n0: np.ndarray, p1: np.ndarray, n1: np.ndarray) -> np.ndarray:
    """Angles (radians) between each contact's inward force and the grasp axis.

    ``p0, p1``: ``(n, 3)`` contacts; ``n0, n1``: their outward unit normals.
    The finger at ``p0`` pushes along ``+axis`` (``axis = (p1 - p0) / |p1 - p0|``)
    and must do so inside the cone about ``-n0``; the finger at ``p1`` pushes
    along ``-axis`` inside the cone about ``-n1``. Returns ``(n, 2)``.
    """
    axis = p1 - p0
    axis = axis / np.linalg.norm(axis, axis=1, keepdims=True)
    c0 = np.clip(np.einsum("ij,ij->i", -n0, axis), -1.0, 1.0)
    c1 = np.clip(np.einsum("ij,ij->i", n1, axis), -1.0, 1.0)
    return np.stack([np.arccos(c0), np.arccos(c1)], axis=1)


def antipodal_mask(p0: np.ndarray, n0: np.ndarray, p1: np.ndarray, n1: np.ndarray, mu: float) -> np.ndarray:
    """``(n,)`` bool: both contacts' friction cones contain the grasp axis (force closure)."""
    return np.all(antipodal_angles(p0, n0, p1, n1) <= friction_half_angle(mu), axis=1)


def _tangent_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ref = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(n, ref)
    t1 /= np.linalg.norm(t1)
    return t1, np.cross(n, t1)


def wrench_space_quality(
    contacts: np.ndarray,
    normals: np.ndarray,
    mu: float,
    *,
    center: np.ndarray | None = None,
    torsion: float = 0.0,
    edges: int = 8,
    length_scale: float | None = None,
) -> float:
    """Ferrari-Canny quality of a grasp: > 0 iff force closure (linearised cones).

    Parameters
    ----------
    contacts : ``(k, 3)`` contact points (metres).
    normals : ``(k, 3)`` outward unit surface normals at the contacts.
    mu : Coulomb friction coefficient.
    center : torque reference point (the centre of mass); default the contacts' mean.
    torsion : soft-finger torsional friction, as the torque per unit normal force
        (metres, about ``mu`` times the pad's effective radius); 0 for point contacts.
    edges : facets of each linearised friction cone.
    length_scale : divides torques so they compare with forces (metres); default
        the largest contact distance from ``center``.
    """
    contacts = np.asarray(contacts, dtype=float)
    normals = np.asarray(normals, dtype=float)
    c = contacts.mean(axis=0) if center is None else np.asarray(center, dtype=float)
    rho = length_scale or max(float(np.max(np.linalg.norm(contacts - c, axis=1))), 1e-9)
    wrenches = []
    phis = 2.0 * np.pi * np.arange(edges) / edges
    for p, n in zip(contacts, normals, strict=True):
        inward = -n / np.linalg.norm(n)
        t1, t2 = _tangent_basis(inward)
        for phi in phis:
            f = inward + mu * (np.cos(phi) * t1 + np.sin(phi) * t2)
            wrenches.append(np.concatenate([f, np.cross(p - c, f) / rho]))
        if torsion > 0.0:
            for sign in (1.0, -1.0):
                wrenches.append(np.concatenate([np.zeros(3), sign * torsion * inward / rho]))
    W = np.asarray(wrenches)
    try:
        hull = ConvexHull(W)
    except QhullError:
        # The primitive wrenches span less than 6 dimensions: some wrench cannot be resisted.
        return 0.0
    # Facet equations are [a, b] with unit a and a.x + b <= 0 inside; the origin's
    # distance to facet i is -b_i, and it is inside iff every -b_i > 0.
    return float(max(0.0, np.min(-hull.equations[:, -1])))
