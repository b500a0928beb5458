"""Camera Roll Histogram (CRH, ``pcl::CRHEstimation``, PCL 1.13) and roll alignment by circular cross-correlation.

The CRH of a view is the 90-bin (4 degree) histogram of the azimuths of its normals about the view axis, each normal
weighted by its component perpendicular to that axis, after the cloud has been rotated so that its centroid lies on
the axis. It is stored as PCL stores it: the real FFT of the histogram normalised to unit sum, packed as
``[DC = 1, Re1, Im1, ..., Re44, Im44, Nyquist]`` (90 floats).

A roll of the camera about its view axis shifts the histogram cyclically, so the roll between two views of the same
surface is the lag maximising the circular cross-correlation of their histograms, computed in the Fourier domain.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from asmteach.core.errors import UserError
from asmteach.plugins.detectors.cvfh.descriptors.vfh import check_cloud

CRH_BINS = 90
CRH_BIN_DEG = 360 // CRH_BINS  # 4 degrees
_FINE = 360  # correlation evaluated at 1 degree by band-limited (zero-padded spectrum) interpolation


def _align_to(axis_from: NDArray[np.float64], axis_to: NDArray[np.float64]) -> Rotation:
    """Smallest rotation taking unit vector ``axis_from`` onto unit vector ``axis_to``."""
    cross = np.cross(axis_from, axis_to)
    s = float(np.linalg.norm(cross))
    c = float(np.dot(axis_from, axis_to))
    if s < 1e-12:
        if c > 0:
            return Rotation.identity()
        # antiparallel: half turn about any axis perpendicular to axis_from
        perp = np.cross(axis_from, [1.0, 0.0, 0.0] if abs(axis_from[0]) < 0.9 else [0.0, 1.0, 0.0])
        return Rotation.from_rotvec(np.pi * perp / np.linalg.norm(perp))
    return Rotation.from_rotvec(cross / s * np.arctan2(s, c))


def roll_histogram(
    normals: ArrayLike, centroid: ArrayLike, *, view_axis: ArrayLike = (0.0, 0.0, 1.0)
) -> NDArray[np.float64]:
    """The 90-bin roll histogram (unit sum) behind :func:`compute_crh`.

    Bin ``k`` holds azimuths ``atan2(n_y, n_x)`` in ``[-180 + 4k, -176 + 4k)`` degrees of the normals after the
    centroid-to-axis rotation, weighted by ``sqrt(n_x^2 + n_y^2)``.
    """
    n = np.asarray(normals, dtype=np.float64)
    axis = np.asarray(view_axis, dtype=np.float64)
    axis_norm = float(np.linalg.norm(axis))
    if axis.shape != (3,) or axis_norm == 0.0:
        raise UserError(f"compute_crh: view_axis must be a non-zero 3-vector, got {view_axis!r}")
    # Express everything in a frame whose z is the view axis (identity for the default camera z axis).
    to_cam = _align_to(axis / axis_norm, np.array([0.0, 0.0, 1.0]))
    c = to_cam.apply(np.asarray(centroid, dtype=np.float64))
    c_norm = float(np.linalg.norm(c))
    if c_norm == 0.0:
        raise UserError("compute_crh: centroid is at the viewpoint; pass the view's centroid in the camera frame")
    # PCL rotates the cloud so the direction from the camera to the centroid becomes the view axis.
    rot = _align_to(c / c_norm, np.array([0.0, 0.0, 1.0])) * to_cam
    nr = rot.apply(n)
    azimuth_deg = np.degrees(np.arctan2(nr[:, 1], nr[:, 0]) + np.pi)
    bins = (azimuth_deg // CRH_BIN_DEG).astype(np.intp) % CRH_BINS
    weights = np.hypot(nr[:, 0], nr[:, 1])
    hist = np.bincount(bins, weights=weights, minlength=CRH_BINS)
    total = float(hist.sum())
    if total <= 0.0:
        raise UserError("compute_crh: every normal is parallel to the view axis; the roll is undefined for this view")
    return hist / total


def compute_crh(
    points: ArrayLike, normals: ArrayLike, centroid: ArrayLike, *, view_axis: ArrayLike = (0.0, 0.0, 1.0)
) -> NDArray[np.float64]:
    """CRH of a view in PCL's layout ``[DC=1, Re1, Im1, ..., Re44, Im44, Nyquist]``.

    Args:
        points: ``(n, 3)`` points, metres, camera frame (checked for shape; PCL's CRH only uses the normals).
        normals: ``(n, 3)`` unit normals, camera frame (NaN rows are left out).
        centroid: ``(3,)`` reference centroid, metres, camera frame (a CVFH region centroid or the view centroid;
            PCL needs it set explicitly).
        view_axis: ``(3,)`` camera viewing direction in the frame of the inputs (camera z for camera-frame clouds).
            For another axis the inputs are first turned by the smallest rotation taking it onto z, which fixes
            the zero of roll; rolls between views are meaningful when both use the same frame and axis.

    Returns:
        ``(90,)`` float descriptor.

    Raises:
        UserError: malformed input, a centroid at the viewpoint, or normals all along the view axis.
    """
    _, n, ok = check_cloud(points, normals, "compute_crh")
    spectrum = np.fft.rfft(roll_histogram(n[ok], centroid, view_axis=view_axis))
    return pack_spectrum(spectrum / spectrum[0].real)


def pack_spectrum(spectrum: NDArray[np.complex128]) -> NDArray[np.float64]:
    """Pack a 46-coefficient real-FFT spectrum into PCL's 90-float CRH layout."""
    out = np.empty(CRH_BINS)
    out[0] = spectrum[0].real
    out[1 : CRH_BINS - 1 : 2] = spectrum[1 : CRH_BINS // 2].real
    out[2 : CRH_BINS - 1 : 2] = spectrum[1 : CRH_BINS // 2].imag
    out[CRH_BINS - 1] = spectrum[CRH_BINS // 2].real
    return out


def unpack_spectrum(crh: ArrayLike) -> NDArray[np.complex128]:
    """Inverse of :func:`pack_spectrum`: the ``(46,)`` complex spectrum of a ``(90,)`` CRH."""
    c = np.asarray(crh, dtype=np.float64)
    if c.shape != (CRH_BINS,) or not np.isfinite(c).all():
        raise UserError(f"CRH must be a finite ({CRH_BINS},) array as compute_crh returns, got shape {c.shape}")
    spectrum = np.zeros(CRH_BINS // 2 + 1, dtype=np.complex128)
    spectrum[0] = c[0]
    spectrum[1 : CRH_BINS // 2] = c[1 : CRH_BINS - 1 : 2] + 1j * c[2 : CRH_BINS - 1 : 2]
    spectrum[CRH_BINS // 2] = c[CRH_BINS - 1]
    return spectrum


def roll_correlation(crh_a: ArrayLike, crh_b: ArrayLike) -> NDArray[np.float64]:
    """Circular cross-correlation ``corr[m] = sum_phi h_a(phi - m deg) h_b(phi)`` at 1 degree steps, ``(360,)``.

    ``corr[m]`` is large when view a rolled by ``+m`` degrees about the view axis looks like view b. It is the
    band-limited interpolation of the 4-degree correlation (the spectrum is zero-padded), scaled so that
    ``sum(corr) / 4`` is the product of the two histograms' sums.
    """
    spec = np.conj(unpack_spectrum(crh_a)) * unpack_spectrum(crh_b)
    # Zero-padding splits the Nyquist coefficient between +45 and -45 cycles; halve it so interpolation is exact.
    spec[-1] *= 0.5
    return np.fft.irfft(spec, n=_FINE) * (_FINE / CRH_BINS)


def crh_roll_candidates(
    crh_a: ArrayLike, crh_b: ArrayLike, *, max_peaks: int = 4, rel_threshold: float = 0.3
) -> list[float]:
    """Roll angles that align view a to view b, best first.

    A returned ``roll`` means: rotating view a by ``roll`` radians about the camera z (view) axis makes its normals'
    roll histogram match view b's. Peaks of the circular cross-correlation (:func:`roll_correlation`) are kept when
    they are local maxima at least ``rel_threshold`` times the highest, at most ``max_peaks`` of them, at least two
    histogram bins (8 degrees) apart. Unlike PCL, the 180-degree partner of every kept peak is added too (when not
    already within 8 degrees of a candidate): views of box-like parts are nearly symmetric under a half turn, and
    the wrong one of the two often wins by a hair.

    Args:
        crh_a: ``(90,)`` CRH of view a (:func:`compute_crh`).
        crh_b: ``(90,)`` CRH of view b.
        max_peaks: most correlation peaks kept before adding their 180-degree partners (so at most
            ``2 * max_peaks`` candidates).
        rel_threshold: peaks below this fraction of the highest correlation are dropped, in ``(0, 1]``.

    Returns:
        Roll angles in radians in ``(-pi, pi]``, ordered by decreasing correlation.

    Raises:
        UserError: malformed CRH or settings.
    """
    if max_peaks < 1:
        raise UserError(f"crh_roll_candidates: max_peaks must be >= 1, got {max_peaks}")
    if not 0.0 < rel_threshold <= 1.0:
        raise UserError(f"crh_roll_candidates: rel_threshold must be in (0, 1], got {rel_threshold}")
    corr = roll_correlation(crh_a, crh_b)
    is_peak = (corr >= np.roll(corr, 1)) & (corr > np.roll(corr, -1))  # circular local maxima, plateaus once
    peaks = np.flatnonzero(is_peak & (corr >= rel_threshold * corr.max()))
    peaks = peaks[np.argsort(-corr[peaks], kind="stable")]
    min_sep = 2 * CRH_BIN_DEG  # in fine steps (1 degree each)

    def far(m: int, kept: list[int]) -> bool:
        return all(min(abs(m - k) % _FINE, _FINE - abs(m - k) % _FINE) >= min_sep for k in kept)

    kept: list[int] = []
    for m in peaks:
        if far(int(m), kept):
            kept.append(int(m))
        if len(kept) == max_peaks:
            break
    candidates = list(kept)
    for m in kept:
        partner = (m + _FINE // 2) % _FINE
        if far(partner, candidates):
            candidates.append(partner)
    candidates.sort(key=lambda m: -corr[m])
    degrees = np.array(candidates, dtype=np.float64) * (360.0 / _FINE)
    return [float(r) for r in np.radians(np.where(degrees > 180.0, degrees - 360.0, degrees))]
