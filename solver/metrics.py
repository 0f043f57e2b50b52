"""Accuracy figures of a recovered surface: the paper's RMS and RRMS (PAPER.tex Eqs. 35-36).

Units: deformations in m, so RMS in m; RRMS dimensionless. The paper's Eq. 35 divides by N^2
but means the grid points inside the aperture: raysim averages over exactly those points
(r < D/2 on the N x N cell-centred grid) where both maps are finite.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from solver.aperture import ApertureGrid


def _inside(grid: ApertureGrid, *maps: NDArray[np.float64]) -> NDArray[np.bool_]:
    use = grid.mask.copy()
    for m in maps:
        use &= np.isfinite(m)
    return use


def rms(grid: ApertureGrid, values: NDArray[np.float64]) -> float:
    """Root mean square (m) of ``values`` over the aperture's grid points."""
    use = _inside(grid, values)
    return float(np.sqrt(np.mean(values[use] ** 2)))


def peak_to_peak(grid: ApertureGrid, values: NDArray[np.float64]) -> float:
    """Peak-to-peak M (m) of ``values`` over the aperture's grid points (the paper's M_delta)."""
    use = _inside(grid, values)
    return float(np.ptp(values[use]))


def rms_error(grid: ApertureGrid, recovered: NDArray[np.float64],
              truth: NDArray[np.float64]) -> float:
    """RMS (m) of recovered - truth over the aperture's grid points (paper Eq. 35)."""
    use = _inside(grid, recovered, truth)
    return float(np.sqrt(np.mean((recovered[use] - truth[use]) ** 2)))


def rrms(grid: ApertureGrid, recovered: NDArray[np.float64], truth: NDArray[np.float64],
         M: float | None = None) -> float:
    """RRMS = RMS / M (paper Eq. 36); M defaults to the peak-to-peak of ``truth``."""
    M = peak_to_peak(grid, truth) if M is None else M
    return rms_error(grid, recovered, truth) / M
