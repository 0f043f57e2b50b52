"""The map continued outside the aperture disk, for the forward model's interpolating spline.

Frame and units: the aperture grid of :mod:`solver.aperture` (x, y and delta in m, arrays
indexed [y, x]).

The refinement's forward models see a surface estimate through a bicubic spline of the grid
values (:class:`raysim.surface.gridded.GriddedMap`), and near the rim that spline draws on the
grid points outside the disk. A Laplace fill seeded from the staircase of inside points
(:class:`raysim.surface.gridded.HarmonicFill` alone) flattens the map there: the spline then
bends within a grid step inside the rim, by an amount that changes with azimuth, and a scan row
whose rays come from the last millimetres inside the rim (a row whose outer edge meets the rim
image, which :func:`solver.resample.usable_rows` admits) reads an FA the surface does not make.
On a 50 m dish (F/D = 0.4, 2 deg rows ending 0.01 deg inside the rim image) that took a map of
Z(12, 6) from 27 um of error to 90 um, and the paper's deformation from 0.44 to 2.6 um.

Here each grid point less than :data:`BAND` steps outside the rim takes the value at its
position of the quadratic in x, y fitted by least squares to the inside points within
:data:`FIT_RADIUS` steps of it: the map's own smooth continuation, with its slope and
curvature. The points beyond take the Laplace fill of the inside and the band, which the
spline inside the disk does not reach. Both steps are linear in the inside values, so the
continuation has an exact transpose (the Gauss-Newton Jacobian's VJP, :mod:`solver.jacobian`).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from raysim.surface.gridded import HarmonicFill
from solver.aperture import ApertureGrid

#: grid steps beyond the rim that take the fitted continuation: the interpolating spline is
#: global, a grid value's weight falling about 3.7 times a step, so the Laplace fill's values
#: start where their weight at the rim is under 1 % (at 2.5 steps the spline's slope there
#: stopped converging at 0.6 % of the surface's)
BAND = 4.5
#: grid steps about a band point within which inside points enter its fit (about 56 of them
#: next to the rim; a wider radius where fewer than MIN_POINTS fall inside)
FIT_RADIUS = 6.0
MIN_POINTS = 12  # the fit's six coefficients want twice as many points; a wider radius else


class RimContinuation:
    """The continuation of a map's inside values to every point of its grid (see the module).

    Built once per grid; calling it with values of the grid's shape returns a copy whose
    points outside the disk hold the continuation of the inside values (those given outside
    are ignored); :meth:`transpose` is its adjoint.
    """

    def __init__(self, grid: ApertureGrid) -> None:
        self.mask = grid.mask
        X, Y = grid.XY
        outside = ~self.mask
        self.band = outside & (grid.r < grid.a + BAND * grid.h)
        inside = np.column_stack([X[self.mask], Y[self.mask]]) / grid.h
        targets = np.column_stack([X[self.band], Y[self.band]]) / grid.h
        self.weights = _quadratic_extrapolation(inside, targets)
        self.fill = HarmonicFill(outside & ~self.band)

    def __call__(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        """``values`` (m, the grid's shape) continued outside the disk (a copy, float64)."""
        out = np.array(values, dtype=np.float64, copy=True)
        out[self.band] = self.weights @ out[self.mask]
        return self.fill(out)

    def transpose(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        """The adjoint: a gradient on the whole grid -> on the inside values (zero outside)."""
        back = self.fill.transpose(values)
        out = np.zeros_like(back)
        out[self.mask] = back[self.mask] + self.weights.T @ back[self.band]
        return out


def _quadratic_extrapolation(inside: NDArray[np.float64], targets: NDArray[np.float64]
                             ) -> sp.csr_matrix:
    """Weights (targets x inside) that evaluate at each target point the least-squares
    quadratic of the inside points near it (coordinates in grid steps)."""
    tree = cKDTree(inside)
    rows, cols, vals = [], [], []
    for k, target in enumerate(targets):
        radius = FIT_RADIUS
        near = tree.query_ball_point(target, radius)
        while len(near) < MIN_POINTS:
            radius *= 1.5
            near = tree.query_ball_point(target, radius)
        d = inside[near] - target
        V = np.column_stack([np.ones(len(near)), d[:, 0], d[:, 1], d[:, 0] ** 2,
                             d[:, 0] * d[:, 1], d[:, 1] ** 2])
        # the fitted quadratic's value at the target is its constant term
        rows.append(np.full(len(near), k))
        cols.append(np.asarray(near))
        vals.append(np.linalg.pinv(V)[0])
    shape = (len(targets), len(inside))
    if not rows:
        return sp.csr_matrix(shape)
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=shape)


@lru_cache(maxsize=4)
def rim_continuation(D: float, N: int) -> RimContinuation:
    """The :class:`RimContinuation` of the grid (D, N), built once per grid (the refinement
    calls it every iteration)."""
    return RimContinuation(ApertureGrid(D, N))
