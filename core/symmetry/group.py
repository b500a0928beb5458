"""A part's symmetry group: the proper rotations that map its surface onto itself, and its equivalent transforms.

Candidates for the whole group: the 24 rotations of the cube group in the
part frame and in the principal frame (boxes, cubes), the cyclic group about
each principal and part-frame axis (prisms, pegs, wheels: up to
``max_order``), and the half-turns about axes perpendicular to a symmetry
axis (the dihedral flips of a hexagonal peg). A surface of revolution (a
tube within ``tol`` of a cylinder) is symmetric under every turn about its
axis; it gets the finite group ``D_max_order`` (10 deg steps by default), so
an error figure may keep up to half a step of a turn that changes nothing.

Units: metres, radians; frames: the part frame.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from asmteach.core import geometry
from asmteach.core.symmetry.finder import SymmetryFinder, axis_rotations

# Two symmetries closer than this (radians) are one; the flips found from a histogram are up to
# a degree or two off the exact ones and still map within a 0.5 mm tol; D_36 flips are 5 deg apart.
_SAME_RAD = np.radians(2.5)


def principal_frame(mesh: trimesh.Trimesh) -> np.ndarray:
    """``(3, 3)`` right-handed rotation whose columns are the mesh's principal axes of inertia.

    A new array: trimesh returns its cached principal axes read-only, and
    flipping one in place raised ``ValueError`` for every part whose axes
    came out left-handed.
    """
    F = np.array(mesh.principal_inertia_vectors, dtype=float).T  # np.array copies
    if np.linalg.det(F) < 0.0:
        F = F * np.array([1.0, 1.0, -1.0])
    return F


def _unique(rotations: list[np.ndarray], atol: float = 1e-6) -> list[np.ndarray]:
    out: list[np.ndarray] = []
    for R in rotations:
        if not any(np.allclose(R, S, atol=atol) for S in out):
            out.append(R)
    return out


def _perpendicular_flips(
    finder: SymmetryFinder, samples: np.ndarray, axis: np.ndarray, order: int, bins: int = 720
) -> list[np.ndarray]:
    """Half-turns about axes perpendicular to ``axis`` (through the centre) that map the part onto itself.

    A dihedral group ``D_m`` has ``m`` such flips, ``pi / m`` apart, so one
    flip found gives them all. A flip about the line at angle ``phi`` takes
    a surface point at (angle ``t``, radius ``r``, height ``h``) about
    ``axis`` to (``2 phi - t``, ``r``, ``-h``); the histogram ``H(t, r, h)`` of
    centred surface ``samples`` then matches its own image, so the circular
    convolution over ``t`` of ``H(., r, h)`` with ``H(., r, -h)`` (one FFT)
    peaks at ``2 phi``. The highest peaks are the candidates, checked
    exactly. Tessellation-free: a 64-sided rim gives no preferred vertex.
    """
    axis = axis / np.linalg.norm(axis)
    u = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    h = samples @ axis
    r = np.hypot(samples @ u, samples @ v)
    t = np.mod(np.arctan2(samples @ v, samples @ u), 2.0 * np.pi)
    hmax, rmax = float(np.abs(h).max()) + 1e-12, float(r.max()) + 1e-12
    H, _ = np.histogramdd(np.c_[t, r, h], bins=(bins, 8, 8), range=((0.0, 2.0 * np.pi), (0.0, rmax), (-hmax, hmax)))
    F = np.fft.rfft(H, axis=0)
    conv = np.fft.irfft((F * F[:, :, ::-1]).sum(axis=(1, 2)), n=bins, axis=0)  # H(., r, h) * H(., r, -h)
    step = 2.0 * np.pi / bins
    rots = axis_rotations(axis, 2.0 * np.pi * np.arange(order) / order)
    for peak in np.argsort(conv)[::-1][:4]:
        phi = 0.5 * (peak + 0.5) * step  # the bin centre of 2 phi; refined by testing its neighbours too
        for dphi in (0.0, -0.5 * step, 0.5 * step):
            d = np.cos(phi + dphi) * u + np.sin(phi + dphi) * v
            flip = Rotation.from_rotvec(np.pi * d).as_matrix()
            if finder.maps(flip):
                return [R @ flip for R in rots]
    return []


def part_symmetries(
    mesh: trimesh.Trimesh, com: np.ndarray, tol: float = 0.0005, max_order: int = 36
) -> list[np.ndarray]:
    """Proper rotations (``(4, 4)``, part frame, about the centre of mass ``com``) that map the part onto itself.

    ``tol`` (metres) is how far a rotated surface may stray from the surface
    and still be the same part (0.5 mm: a pose that differs by such a turn
    puts the same solid in the same place, for grasping and assembling it).
    The identity comes first; see the module docstring for the candidates.
    """
    com = np.asarray(com, dtype=float)
    finder = SymmetryFinder(
        mesh, np.asarray(mesh.convex_hull.vertices), com, tol=tol, max_order=max_order, corners=False
    )
    frames = [np.eye(3), principal_frame(mesh)]
    cube = Rotation.create_group("O").as_matrix()
    candidates = [F @ C @ F.T for F in frames for C in cube]
    samples = trimesh.sample.sample_surface(mesh, 4000, seed=0)[0] - com
    for axis in (F[:, k] for F in frames for k in range(3)):
        m = finder.order(axis)
        if m > 1:
            candidates += list(axis_rotations(axis, 2.0 * np.pi * np.arange(1, m) / m))
            candidates += _perpendicular_flips(finder, samples, axis, m)
    found = [np.eye(3)]
    for R in _unique(candidates):
        # within tol, a turn a fraction of a degree off a symmetry maps too: keep the first (exact) one
        if not any(geometry.rotation_distance(R, S) < _SAME_RAD for S in found) and finder.maps(R):
            found.append(R)
    return [geometry.from_rotation(R, com - R @ com) for R in found]


def equivalent_transforms(mesh: trimesh.Trimesh, com: np.ndarray, tol: float = 0.0005) -> np.ndarray:
    """Part-frame transforms ``(m, 4, 4)`` that map the part onto itself (about the centre of mass).

    :func:`part_symmetries`, whose surfaces of revolution get turns in 10 deg steps only (an error could
    keep 5 deg of a turn that changes nothing), times every 1 deg turn about the axis of revolution when
    the part has one (a principal axis about which turns of 7 and 31 deg map it onto itself).
    """
    group = np.asarray(part_symmetries(mesh, com, tol))
    finder = SymmetryFinder(mesh, np.asarray(mesh.convex_hull.vertices), com, tol=tol, corners=False)
    for axis in principal_frame(mesh).T:
        if all(finder.maps(R) for R in axis_rotations(axis, np.radians([7.0, 31.0]))):
            turns = [geometry.from_rotation(R, com - R @ com) for R in axis_rotations(axis, np.radians(np.arange(360)))]
            return np.einsum("aij,bjk->abik", group, np.asarray(turns)).reshape(-1, 4, 4)
    return group
