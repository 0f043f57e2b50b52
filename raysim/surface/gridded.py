"""Surfaces given on a regular grid: the gridded deformation map and the harmonic fill of holes.

Frame and units as :mod:`raysim.surface.deformation`: x, y in metres in the aperture plane,
delta in metres along +z, arrays indexed [y, x].

:class:`HarmonicFill` fills the missing cells of a grid with the discrete harmonic function
(5-point Laplace equation, zero normal derivative at the grid's outer edge) that takes the
known values: the smoothest continuation, with no new extremum. It fills the NaN samples of
a gridded map, and the solver's continuation outside the aperture disk beyond the band next to
the rim that the map's own local fit fills (:mod:`solver.continuation`), with its transpose
for the model's Jacobian (:mod:`solver.jacobian`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from raysim.errors import SceneError
from raysim.surface.deformation import Deformation

Array = NDArray[np.float64]


class HarmonicFill:
    """The discrete Laplace continuation into the cells ``missing`` (bool, (ny, nx)) of a grid.

    Assembled and factorised once (sparse LU) for the pattern; calling it with values of the
    grid's shape returns a copy whose missing cells solve the 5-point Laplace equation with
    the known cells as boundary values. Each missing cell averages its neighbours inside the
    grid (fewer than four at the edge: a zero normal derivative there).
    """

    def __init__(self, missing: NDArray[np.bool_]) -> None:
        self.missing = np.asarray(missing, dtype=bool)
        ny, nx = self.missing.shape
        n = int(np.count_nonzero(self.missing))
        index = np.full(self.missing.shape, -1, dtype=np.int64)
        index[self.missing] = np.arange(n)
        jj, ii = np.nonzero(self.missing)
        rows, cols, vals = [np.arange(n)], [np.arange(n)], []
        diag = np.zeros(n)
        self._known: list[tuple[NDArray, NDArray, NDArray]] = []  # (unknown, j, i) pairs
        for dj, di in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            nj, ni = jj + dj, ii + di
            ok = (nj >= 0) & (nj < ny) & (ni >= 0) & (ni < nx)
            diag += ok
            k = np.flatnonzero(ok)
            neighbour = index[nj[k], ni[k]]
            unknown = neighbour >= 0
            rows.append(k[unknown])
            cols.append(neighbour[unknown])
            vals.append(-np.ones(np.count_nonzero(unknown)))
            self._known.append((k[~unknown], nj[k[~unknown]], ni[k[~unknown]]))
        self._n = n
        if n:
            A = sp.csc_matrix((np.concatenate([diag, *vals]),
                               (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
            self._lu = spla.splu(A)

    def __call__(self, values: Array) -> Array:
        """``values`` with the missing cells filled (a copy, float64)."""
        filled = np.array(values, dtype=np.float64, copy=True)
        if not self._n:
            return filled
        rhs = np.zeros(self._n)
        for k, nj, ni in self._known:
            np.add.at(rhs, k, filled[nj, ni])
        filled[self.missing] = self._lu.solve(rhs)
        return filled

    def transpose(self, values: Array) -> Array:
        """The adjoint of the fill (a linear map of the grid's values, which ignores the
        missing cells' inputs): a copy of ``values`` whose missing cells are zero and whose
        known cells gain what the missing cells drew from them, (A^-T g) per neighbour."""
        back = np.array(values, dtype=np.float64, copy=True)
        if not self._n:
            return back
        t = self._lu.solve(np.ascontiguousarray(back[self.missing]), trans="T")
        back[self.missing] = 0.0
        for k, nj, ni in self._known:
            np.add.at(back, (nj, ni), t[k])
        return back


@dataclass(frozen=True, eq=False)
class GriddedMap(Deformation):
    """A deformation given on a regular grid: x (nx,), y (ny,) in m, dz (ny, nx) in m.

    Interpolated with a bicubic spline (continuous slopes). NaN samples (outside the aperture,
    say) are first filled by a harmonic extension of the known values, so the surface stays
    smooth up to and beyond the rim.
    """

    x: NDArray[np.float64]
    y: NDArray[np.float64]
    dz: NDArray[np.float64]
    scale: float = 1.0

    def __post_init__(self) -> None:
        from scipy.interpolate import RectBivariateSpline

        x = np.asarray(self.x, dtype=np.float64)
        y = np.asarray(self.y, dtype=np.float64)
        dz = np.asarray(self.dz, dtype=np.float64)
        if dz.shape != (len(y), len(x)) or len(x) < 4 or len(y) < 4:
            raise SceneError(f"gridded deformation needs dz of shape (ny, nx) with nx, ny >= 4, "
                             f"got {dz.shape} for nx={len(x)}, ny={len(y)}")
        if np.any(np.diff(x) <= 0) or np.any(np.diff(y) <= 0):
            raise SceneError("gridded deformation: x and y must increase strictly")
        if not np.any(np.isfinite(dz)):
            raise SceneError("gridded deformation holds no finite value")
        filled = HarmonicFill(~np.isfinite(dz))(dz)
        spline = RectBivariateSpline(y, x, filled * self.scale, kx=3, ky=3, s=0)
        object.__setattr__(self, "_spline", spline)

    def __call__(self, x, y, panel=None):
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        shape = np.broadcast(x, y).shape
        xb, yb = np.broadcast_to(x, shape).ravel(), np.broadcast_to(y, shape).ravel()
        return self._spline.ev(yb, xb).reshape(shape)

    def gradient(self, x, y, panel=None):
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        shape = np.broadcast(x, y).shape
        xb, yb = np.broadcast_to(x, shape).ravel(), np.broadcast_to(y, shape).ravel()
        gx = self._spline.ev(yb, xb, dy=1).reshape(shape)
        gy = self._spline.ev(yb, xb, dx=1).reshape(shape)
        return gx, gy

    def describe(self) -> str:
        return f"gridded map {len(self.y)} x {len(self.x)}"
