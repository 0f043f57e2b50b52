"""The aperture grid: N x N cell-centred points over the square [-D/2, D/2]^2 in the z = 0 plane.

Frame (docs/physics.md): x, y in metres in the aperture plane, the axis at the origin. Point (i, j)
sits at x_i = -D/2 + (i + 1/2) h, y_j = -D/2 + (j + 1/2) h with h = D / N; arrays are indexed
``[j, i]`` (y first, as SurfaceMaps and datasets store them). The aperture is the open disk
r < D/2. One grid serves every layer: the solver's Poisson problem, the SurfaceMap contract,
the dataset's deformation maps (with the panel layout, so panel errors are evaluated on the
panel each point lies on) and the pictures.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.errors import GridError

Array = NDArray[np.float64]


class PanelMap(Protocol):
    """A panel layout as the grid needs it: the panel id under each point (-1 in a gap)."""

    def panel_at(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.int64]: ...


class SurfaceFunction(Protocol):
    """delta(x, y, panel) in metres, ``panel`` the panel ids of the points or None."""

    def __call__(self, x: Array, y: Array, panel: NDArray[np.int64] | None = None, /) -> Array: ...


def cell_centres(D: float, N: int) -> Array:
    """The N cell centres -D/2 + (i + 1/2) D / N (m) across a diameter D (m)."""
    return -0.5 * D + (np.arange(N) + 0.5) * (D / N)


@dataclass(frozen=True)
class ApertureGrid:
    """Cell-centred N x N grid over a dish of diameter ``D`` (m).

    ``layout`` (optional) gives the panel under each point, for deformations that depend on
    the panel (rigid panel errors); grids without one treat the dish as one piece.
    """

    D: float
    N: int
    layout: PanelMap | None = None

    def __post_init__(self) -> None:
        if int(self.N) != self.N or self.N < 2:
            raise GridError(f"an aperture grid needs an integer N >= 2 points, got {self.N}")
        if not self.D > 0:
            raise GridError(f"diameter must be > 0 m, got {self.D}")

    @property
    def a(self) -> float:
        """Aperture radius D / 2 (m)."""
        return 0.5 * self.D

    @property
    def h(self) -> float:
        """Grid step D / N (m)."""
        return self.D / self.N

    @cached_property
    def x(self) -> Array:
        """Cell-centre x coordinates (m), shape (N,); the same values serve as y."""
        return cell_centres(self.D, int(self.N))

    @property
    def y(self) -> Array:
        return self.x

    @cached_property
    def XY(self) -> tuple[Array, Array]:
        """Coordinates of every point, two (N, N) arrays indexed [j, i]."""
        return np.meshgrid(self.x, self.y, indexing="xy")

    @cached_property
    def r(self) -> Array:
        """Distance from the axis (m), (N, N)."""
        X, Y = self.XY
        return np.hypot(X, Y)

    @cached_property
    def phi(self) -> Array:
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

    @cached_property
    def panel(self) -> NDArray[np.int64] | None:
        """Panel id under each point (-1 in a gap), (N, N); None without a layout."""
        if self.layout is None:
            return None
        X, Y = self.XY
        return np.asarray(self.layout.panel_at(X, Y), dtype=np.int64)

    def masked(self, values: ArrayLike) -> Array:
        """``values`` (N, N) with NaN outside the aperture (a copy)."""
        out = np.array(values, dtype=np.float64, copy=True)
        out[~self.mask] = np.nan
        return out

    def evaluate(self, deformation: SurfaceFunction) -> Array:
        """delta (m) of ``deformation`` at the points inside the aperture, NaN outside.

        Each point is evaluated on the panel it lies on when the grid has a layout.
        """
        X, Y = self.XY
        inside = self.mask
        out = np.full(X.shape, np.nan)
        panel = None if self.panel is None else self.panel[inside]
        out[inside] = deformation(X[inside], Y[inside], panel)
        return out

    def rms(self, deformation: SurfaceFunction) -> float:
        """RMS of delta over the points inside the aperture (m), about zero (no mean removed)."""
        values = self.evaluate(deformation)
        return float(np.sqrt(np.nanmean(values * values)))


__all__ = ["ApertureGrid", "PanelMap", "SurfaceFunction", "cell_centres"]
