"""The numbers of ``raysim check``: how far GO's maps are from the wave engine's, per cell, over
the usable sphere and per theta band, and the panel gaps' signature in both.

Maps are (n_theta, n_phi) arrays on the probe sphere (theta from -z at the focus, rad).
"Usable" is theta <= the rim image minus 2 deg (the measure of docs/engines.md): beyond it the
rim's own diffraction, which no inversion uses, dominates. Relative figures are dimensionless
(multiply by 100 for per cent).

- ideal difference: RMS(I_GO - I_wave) / RMS(I_wave) over the usable cells, ideal reflector
  (a ratio of RMS values, so the wave's dark diffraction rings, where I_wave is near zero, do
  not dominate it as they do a per-cell relative difference).
- FA difference: RMS(FA_GO - FA_wave) / RMS(FA_wave), FA = I_ideal / I_def - 1: what the
  inversion sees, relative to the signal.
- gap signature: the cells GO darkens (ideal cell mean over the smooth paraboloid's,
  :func:`raysim.maps.sphere.ideal_go_cell_mean`, below 99 % of that ratio's median over the
  usable cells: on a coarse grid every cell holds some gap) and the mean intensity there
  relative to the median of its theta row (a ring gap's row, dark as a whole, relative to the
  rows beside it), in GO and in the wave data: GO's lines are black, the wave's are shallow
  dips spread over a Fresnel zone, or lost in its ripple.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from raysim.maps.sphere import SphereGrid, ideal_go_cell_mean, theta_rim

USABLE_MARGIN = math.radians(2.0)  # rad inside the rim image
BAND_WIDTH = math.radians(10.0)
DARK = 0.99  # a GO cell 1 % darker than the typical cell (against the smooth dish) is on a gap line


def usable(sphere: SphereGrid, D: float, F: float) -> NDArray[np.bool_]:
    """Theta rows (n_theta,) at or inside the rim image minus 2 deg."""
    return sphere.theta <= theta_rim(D, F) - USABLE_MARGIN


def rms_ratio(a: NDArray, b: NDArray, mask: NDArray[np.bool_]) -> float:
    """RMS(a - b) / RMS(b) over ``mask`` (finite cells of both)."""
    keep = mask & np.isfinite(a) & np.isfinite(b)
    if not keep.any():
        return math.nan
    scale = np.sqrt(np.mean(b[keep] ** 2))
    return float(np.sqrt(np.mean((a[keep] - b[keep]) ** 2)) / scale) if scale > 0 else math.nan


def rms_of(a: NDArray, mask: NDArray[np.bool_]) -> float:
    keep = mask & np.isfinite(a)
    return float(np.sqrt(np.mean(a[keep] ** 2))) if keep.any() else math.nan


@dataclass(frozen=True)
class Bands:
    """Theta bands of :data:`BAND_WIDTH` up to the usable limit: edges (rad) and per band the
    FA RMS of the wave data, the FA difference over it and the ideal difference."""

    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    fa_rms: NDArray[np.float64]
    fa_difference: NDArray[np.float64]
    ideal_difference: NDArray[np.float64]


def bands(sphere: SphereGrid, D: float, F: float, maps: dict[str, NDArray]) -> Bands:
    """Per-band figures of ``maps`` (``ideal_go``, ``ideal_wave``, ``fa_go``, ``fa_wave``)."""
    limit = theta_rim(D, F) - USABLE_MARGIN
    edges = np.arange(sphere.theta_min, limit, BAND_WIDTH)
    lo, hi = edges, np.minimum(edges + BAND_WIDTH, limit)
    rows = []
    for a, b in zip(lo, hi, strict=True):
        band = ((sphere.theta >= a) & (sphere.theta < b))[:, None] & np.ones((1, sphere.n_phi), bool)
        rows.append((rms_of(maps["fa_wave"], band), rms_ratio(maps["fa_go"], maps["fa_wave"], band),
                     rms_ratio(maps["ideal_go"], maps["ideal_wave"], band)))
    out = np.array(rows, dtype=np.float64).reshape(-1, 3)
    return Bands(lo, hi, out[:, 0], out[:, 1], out[:, 2])


@dataclass(frozen=True)
class GapSignature:
    """GO's dark gap cells and what the wave data show there (see the module docstring)."""

    dark_cells: int
    usable_cells: int
    go_dip: float  # mean over the dark cells of I_GO / row median - 1 (ideal reflector)
    wave_dip: float  # the same of the wave engine's ideal intensity
    wave_dip_elsewhere: float  # the wave's mean |I / row median - 1| off the dark cells
    dark: NDArray[np.bool_]


def gap_signature(sphere: SphereGrid, D: float, F: float, ideal_go: NDArray,
                  ideal_wave: NDArray) -> GapSignature:
    """Where GO's ideal map is darkened by gaps, and the wave's ideal map on the same cells."""
    th = sphere.theta_edges
    smooth = ideal_go_cell_mean(th[:-1], th[1:], F, sphere.radius)[:, None]
    use = usable(sphere, D, F)[:, None] & np.ones((1, sphere.n_phi), bool)
    ratio = ideal_go / smooth
    level = np.nanmedian(np.where(use, ratio, np.nan))  # the gaps' mean loss shifts every cell
    dark = use & (ratio < DARK * level)

    ring = _ring_rows(dark, use)

    def dip(I: NDArray, where: NDArray[np.bool_], absolute: bool = False) -> float:
        with np.errstate(invalid="ignore", divide="ignore"):
            rel = I / _row_levels(I, use, ring) - 1.0
        rel = np.abs(rel) if absolute else rel
        return float(np.nanmean(rel[where])) if where.any() else math.nan

    elsewhere = dip(ideal_wave, use & ~dark, absolute=True)
    if ring.any():  # a ring's dip is against the rows beside it: so is the ripple it must beat
        elsewhere = max(elsewhere, _row_scatter(ideal_wave, use, ring))
    return GapSignature(int(dark.sum()), int(use.sum()), dip(ideal_go, dark), dip(ideal_wave, dark),
                        elsewhere, dark)


#: a theta row whose usable cells are dark in at least this share is on a ring gap
RING_SHARE = 0.5
#: rows each side of a ring gap's row whose medians give its level
RING_NEIGHBOURS = 3


def _ring_rows(dark: NDArray[np.bool_], use: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Theta rows (n_theta,) on a ring gap: most of their usable cells dark."""
    n = use.sum(axis=1)
    return (n > 0) & (dark.sum(axis=1) >= RING_SHARE * np.maximum(n, 1))


def _row_levels(I: NDArray, use: NDArray[np.bool_], ring: NDArray[np.bool_]) -> NDArray:
    """The level (n_theta, 1) each cell of ``I`` is compared with: its theta row's median,
    which takes the wave's axisymmetric diffraction rings out of the comparison; on a ring
    gap's row, where the whole row is dark, the median of the rows' medians within
    :data:`RING_NEIGHBOURS` rows that are not (a ring gap's row measured against itself
    showed no dip at all, in GO as in the wave: 'lost in the ripple' for a 30 % loss)."""
    rows = _row_medians(I, use)
    level = rows.copy()
    clear = np.flatnonzero(~ring & np.isfinite(rows))
    for i in np.flatnonzero(ring):
        near = clear[np.abs(clear - i) <= RING_NEIGHBOURS]
        level[i] = np.median(rows[near]) if len(near) else np.nan
    return level[:, None]


def _row_scatter(I: NDArray, use: NDArray[np.bool_], ring: NDArray[np.bool_]) -> float:
    """Mean |median of a row / median of its clear neighbours' medians - 1| over the rows off
    the ring gaps: how far a row of ``I`` departs from the rows beside it with no gap at all
    (the wave's diffraction rings), the yardstick of a ring gap's dip."""
    rows = _row_medians(I, use)
    clear = np.flatnonzero(~ring & np.isfinite(rows))
    out = [abs(rows[i] / np.median(rows[near]) - 1.0) for i in clear
           if len(near := clear[(np.abs(clear - i) <= RING_NEIGHBOURS) & (clear != i)])]
    return float(np.mean(out)) if out else math.nan


def _row_medians(I: NDArray, use: NDArray[np.bool_]) -> NDArray:
    """Each theta row's median of ``I`` over its usable cells (n_theta,); NaN for a row with
    none (beyond the rim image)."""
    out = np.full(I.shape[0], np.nan)
    for i in np.flatnonzero(use.any(axis=1)):
        values = I[i, use[i]]
        values = values[np.isfinite(values)]
        if values.size:
            out[i] = np.median(values)
    return out
