"""The deformation-intensity equation FA = G Laplacian(delta) (paper Eqs. 28-29) and its inputs.

Frame and units (docs/physics.md): F, R, r, z, d in m; intensities relative to the incident wave
(dimensionless); FA dimensionless; G in m, so Laplacian(delta) = FA / G is in 1/m.

- FA = I_ideal / I_def - 1, from the FieldMap's ``intensity_ideal`` and ``intensity``;
- G = -2 F d / R with d = F + z - R, z = r^2 / (4F), at the aperture point of radius r that the
  ideal GO mapping r = 2F tan(theta/2) sends to the sphere sample.

A measured scan's absolute power scale is unknown: I' = c I turns FA into (1 + FA) / c - 1, a
near-constant offset whose response is a focus-like term. Geometric optics conserves power: all
power the aperture collects reaches the hemisphere, deformed or not, so c is the ratio of the
total powers through the scanned cells (:func:`power_gain`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

GAIN_MODES = ("auto", "known", "power", "none")  # solver.gainmode says what each means


def intensity_ratio_fa(intensity: ArrayLike, intensity_ideal: ArrayLike) -> NDArray[np.float64]:
    """FA = I_ideal / I_def - 1 (dimensionless); NaN (a missing sample) where either intensity
    is missing or not positive: a cell the ideal reflector leaves dark has no ratio to invert
    (FA = -1 there read as a deep bump)."""
    i_def = np.asarray(intensity, dtype=np.float64)
    i_ideal = np.asarray(intensity_ideal, dtype=np.float64)
    good = np.isfinite(i_def) & np.isfinite(i_ideal) & (i_def > 0) & (i_ideal > 0)
    out = np.full(np.broadcast(i_def, i_ideal).shape, np.nan)
    np.divide(i_ideal, i_def, out=out, where=good)
    return np.where(good, out - 1.0, np.nan)


def path_to_sphere(r: ArrayLike, F: float, R: float) -> NDArray[np.float64]:
    """d = F + z - R (m): distance from the ideal reflector point at radius r to the sphere."""
    r = np.asarray(r, dtype=np.float64)
    return F + r * r / (4.0 * F) - R


def G(r: ArrayLike, F: float, R: float) -> NDArray[np.float64]:
    """G = -2 F d / R (m) of the deformation-intensity equation at aperture radius r (m)."""
    return -2.0 * F * path_to_sphere(r, F, R) / R


def power_gain(intensity: ArrayLike, intensity_ideal: ArrayLike,
               cell_area: ArrayLike) -> float:
    """Scale c of a scan relative to its ideal: total power ratio sum(I A) / sum(I_ideal A).

    Over the cells where both samples exist (missing samples drop out of both sums). Exact in
    GO when the scan covers every cell the reflected power can reach.
    """
    i_def = np.asarray(intensity, dtype=np.float64)
    i_ideal = np.asarray(intensity_ideal, dtype=np.float64)
    area = np.broadcast_to(np.asarray(cell_area, dtype=np.float64), i_def.shape)
    both = np.isfinite(i_def) & np.isfinite(i_ideal)
    total_ideal = float(np.sum(i_ideal[both] * area[both]))
    if not total_ideal > 0:
        return 1.0
    return float(np.sum(i_def[both] * area[both])) / total_ideal


#: binomial difference stencils along phi: the n-th difference of white noise of variance v has
#: variance v times the sum of the squared weights (6, 70, 924)
DIFFERENCES = ((1.0, -2.0, 1.0), (1.0, -4.0, 6.0, -4.0, 1.0),
               (1.0, -6.0, 15.0, -20.0, 15.0, -6.0, 1.0))


def noise_variance(fa: ArrayLike, n_rows: int) -> float:
    """Relative variance v of the samples' noise from FA's differences along phi.

    For white noise of variance v, the n-th difference f[j+n/2] - ... has variance v times the
    sum of its squared weights; a smooth signal adds its own n-th derivative times dphi^n. On
    a coarse phi grid the second difference is mostly the signal's curvature (60 cells found a
    noise of 4e-5 in clean simulated data), the sixth far less; a signal that varies cell to
    cell favours the second. Each order gives an estimate, the median absolute deviation
    making it robust to stray samples; the least is taken.
    """
    block = np.asarray(fa, dtype=np.float64)[:n_rows]
    estimates = []
    for weights in DIFFERENCES:
        half = len(weights) // 2
        d = sum(w * np.roll(block, half - k, axis=1) for k, w in enumerate(weights))
        d = d[np.isfinite(d)]
        if d.size < 16:
            return 0.0
        mad = float(np.median(np.abs(d - np.median(d))))
        estimates.append((1.4826 * mad) ** 2 / float(np.sum(np.square(weights))))
    return min(estimates)


def misfit_noise_rms(noise_variance: float, fa: ArrayLike, weight: ArrayLike | float,
                     n_rows: int) -> float:
    """RMS of the noise in a weighted FA misfit over the compared cells (the first ``n_rows``
    rows, where ``fa`` and ``weight`` are finite): sqrt(v mean(weight^2)), v the relative
    noise variance; 0 where nothing is compared or v is not above 0."""
    fa = np.asarray(fa, dtype=np.float64)
    w = np.broadcast_to(np.asarray(weight, dtype=np.float64), fa.shape)[:n_rows]
    cells = np.isfinite(fa[:n_rows]) & np.isfinite(w)
    if not cells.any() or not noise_variance > 0:
        return 0.0
    return float(np.sqrt(noise_variance * np.mean(w[cells] ** 2)))


def stated_noise_variance(intensity: ArrayLike, intensity_std: ArrayLike, n_rows: int) -> float:
    """Relative variance v from a scan's own ``intensity_std``: mean of (std / I)^2."""
    i = np.asarray(intensity, dtype=np.float64)[:n_rows]
    s = np.asarray(intensity_std, dtype=np.float64)[:n_rows]
    ok = np.isfinite(i) & np.isfinite(s) & (i > 0)
    return float(np.mean((s[ok] / i[ok]) ** 2)) if ok.any() else 0.0


def debias(fa: ArrayLike, v: float) -> NDArray[np.float64]:
    """FA with the noise bias of a relative variance v removed: (1 + FA) / (1 + v) - 1."""
    return (1.0 + np.asarray(fa, dtype=np.float64)) / (1.0 + v) - 1.0
