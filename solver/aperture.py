"""The aperture grid: N x N cell-centred points over the square [-D/2, D/2]^2 in the z = 0 plane.

Frame (DESIGN.md): x, y in metres in the aperture plane, the axis at the origin. Point (i, j)
sits at x_i = -D/2 + (i + 1/2) h, y_j = -D/2 + (j + 1/2) h with h = D / N; arrays are indexed
``[j, i]`` (y first, as the SurfaceMap stores them). The aperture is the open disk r < D/2.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from solver.errors import SolverError

MIN_N = 16


@dataclass(frozen=True)
class ApertureGrid:
    """Cell-centred N x N grid over a dish of diameter ``D`` (m)."""

    D: float
    N: int

    def __post_init__(self) -> None:
        if int(self.N) != self.N or self.N < MIN_N:
            raise SolverError(f"grid N must be an integer >= {MIN_N}, got {self.N}")
        if not self.D > 0:
            raise SolverError(f"diameter must be > 0 m, got {self.D}")

    @property
    def a(self) -> float:
        """Aperture radius D / 2 (m)."""
        return 0.5 * self.D

    @property
    def h(self) -> float:
        """Grid step D / N (m)."""
        return self.D / self.N

    @cached_property
    def x(self) -> NDArray[np.float64]:
        """Cell-centre x coordinates (m), shape (N,); the same values serve as y."""
        return -self.a + (np.arange(self.N) + 0.5) * self.h

    @property
    def y(self) -> NDArray[np.float64]:
        return self.x

    @cached_property
    def XY(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Coordinates of every point, two (N, N) arrays indexed [j, i]."""
        return np.meshgrid(self.x, self.y, indexing="xy")

    @cached_property
    def r(self) -> NDArray[np.float64]:
        """Distance from the axis (m), (N, N)."""
        X, Y = self.XY
        return np.hypot(X, Y)

    @cached_property
    def phi(self) -> NDArray[np.float64]:
        """Azimuth atan2(y, x) in [0, 2 pi) (rad), (N, N)."""
        X, Y = self.XY
        return np.mod(np.arctan2(Y, X), 2.0 * np.pi)

    @cached_property
    def mask(self) -> NDArray[np.bool_]:
        """True for points inside the aperture, r < D/2."""
        return self.r < self.a

    @property
    def n_inside(self) -> int:
        """Number of grid points inside the aperture."""
        return int(np.count_nonzero(self.mask))

    def masked(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        """``values`` (N, N) with NaN outside the aperture (a copy)."""
        out = np.array(values, dtype=np.float64, copy=True)
        out[~self.mask] = np.nan
        return out
