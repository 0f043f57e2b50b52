"""The solver's aperture grid: :class:`raysim.maps.aperture.ApertureGrid` and its smallest size.

The grid itself (N x N cell centres over [-D/2, D/2]^2, arrays indexed [y, x], the disk
r < D/2) is the one every layer shares and lives in :mod:`raysim.maps.aperture`; it is
re-exported here, where the solver's modules and users have always found it. The Poisson
solvers need a few points across the disk for their stencils and multigrid levels:
:func:`check_grid` refuses grids under :data:`MIN_N` with a :class:`SolverError`.
"""

from __future__ import annotations

from raysim.maps.aperture import ApertureGrid
from solver.errors import SolverError

MIN_N = 16


def check_grid(grid: ApertureGrid) -> ApertureGrid:
    """``grid`` when the solver can work on it (N >= :data:`MIN_N`), else SolverError."""
    if grid.N < MIN_N:
        raise SolverError(f"grid N must be an integer >= {MIN_N}, got {grid.N}")
    return grid


def solver_grid(D: float, N: int) -> ApertureGrid:
    """The aperture grid of a dish ``D`` (m) with N points across, checked for the solver."""
    if int(N) != N or N < MIN_N:
        raise SolverError(f"grid N must be an integer >= {MIN_N}, got {N}")
    return ApertureGrid(float(D), int(N))


__all__ = ["MIN_N", "ApertureGrid", "check_grid", "solver_grid"]
