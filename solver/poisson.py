"""Poisson solvers on the aperture disk: Laplacian(delta) = f in r < D/2, delta = g on r = D/2.

Frame and units: the aperture grid of :mod:`solver.aperture` (x, y in m, arrays [j, i]); f in
1/m (for the deformation-intensity equation f = FA / G), g and delta in m.

Discretisation: the 5-point Laplacian on the grid points inside the disk, with Shortley-Weller
irregular stars where an arm of the star leaves the disk: that arm is shortened to end on the
true circle r = D/2, where the Dirichlet value sits (Shortley & Weller, J. Appl. Phys. 9, 334,
1938). In x (and likewise in y), with arm lengths h_E, h_W,

    delta_xx ~ 2 / (h_E + h_W) * ((delta_E - delta_0) / h_E - (delta_0 - delta_W) / h_W),

which is the regular star when both arms equal h. The solution converges at second order in h.
The matrix is a non-symmetric M-matrix; every disk solver below works on this one matrix:

- ``direct``: sparse LU (SuperLU, cached per grid), exact to rounding;
- ``multigrid``: classical algebraic multigrid (pyamg Ruge-Stuben V-cycles, cached per grid);
- ``gauss-seidel``: lexicographic Gauss-Seidel sweeps (the paper's FDM solver, Eq. 33); a fixed
  ``iterations`` (the paper used 1000) stops there, converged or not;
- ``sor``: the same sweeps over-relaxed (omega near its optimum for the disk by default);
- ``fft``: the paper's comparison, a fast sine transform on the enclosing square with delta = 0
  on the square's edge; it solves a different problem (the rim of the disk is not a boundary),
  takes no rim values, and agrees with the disk solvers only in the square it solves.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
import scipy.fft
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from solver.aperture import ApertureGrid, check_grid
from solver.errors import SolverError

SOLVERS = ("direct", "multigrid", "gauss-seidel", "sor", "fft")
DISK_SOLVERS = ("direct", "multigrid", "gauss-seidel", "sor")
J01 = 2.404825557695773  # first zero of the Bessel function J0


@dataclass
class SolveInfo:
    """What a solve did: solver name, iterations, relative residual, converged or not."""

    solver: str
    iterations: int = 0
    residual: float = 0.0
    converged: bool = True
    omega: float = 1.0
    note: str = ""


@dataclass
class DiskLaplacian:
    """The Shortley-Weller Laplacian on one aperture grid, with its cached factorisations.

    ``A`` (n x n) acts on the n unknowns inside the disk (row-major order of the grid);
    ``B`` (n x m) carries the Dirichlet values at the m points where stars meet the circle,
    whose azimuths are ``rim_phi`` (rad). Then Laplacian(delta) = A u + B g.
    """

    grid: ApertureGrid
    A: sp.csr_matrix
    B: sp.csr_matrix
    rim_phi: NDArray[np.float64]
    _lu: object = field(default=None, repr=False)
    _amg: object = field(default=None, repr=False)

    @property
    def n(self) -> int:
        return self.A.shape[0]

    def boundary_term(self, g) -> NDArray[np.float64]:
        """B g for rim values ``g``: None (zero), a callable g(phi) (m), or values at rim_phi."""
        if g is None:
            return np.zeros(self.n)
        values = g(self.rim_phi) if callable(g) else np.asarray(g, dtype=np.float64)
        return self.B @ values

    def lu(self):
        if self._lu is None:
            self._lu = spla.splu(self.A.tocsc(), permc_spec="COLAMD")
        return self._lu

    def amg(self):
        if self._amg is None:
            import pyamg

            self._amg = pyamg.ruge_stuben_solver(self.A, max_coarse=50)
        return self._amg


def _arm(x0, y0, a, axis: int, sign: int):
    """Distance (m) from inside points (x0, y0) along +-x or +-y to the circle r = a."""
    along, across = (x0, y0) if axis == 0 else (y0, x0)
    reach = np.sqrt(np.maximum(a * a - across * across, 0.0))
    return reach - sign * along


@lru_cache(maxsize=8)
def disk_laplacian(D: float, N: int) -> DiskLaplacian:
    """Assemble (and cache) the Shortley-Weller Laplacian on the N x N grid of a dish D (m)."""
    grid = ApertureGrid(float(D), int(N))
    h, a, mask = grid.h, grid.a, grid.mask
    index = np.full((N, N), -1, dtype=np.int64)
    index[mask] = np.arange(grid.n_inside)
    jj, ii = np.nonzero(mask)
    X, Y = grid.XY
    x0, y0 = X[mask], Y[mask]
    rows = [np.arange(grid.n_inside)]
    cols = [np.arange(grid.n_inside)]
    diag = np.zeros(grid.n_inside)
    vals: list[NDArray[np.float64]] = []
    b_rows, b_phi, b_vals = [], [], []
    for axis in (0, 1):
        arms, nbrs = [], []
        for sign in (1, -1):
            ni = ii + sign * (axis == 0)
            nj = jj + sign * (axis == 1)
            ok = (ni >= 0) & (ni < N) & (nj >= 0) & (nj < N)
            nb = np.full(ii.shape, -1)
            nb[ok] = index[nj[ok], ni[ok]]
            arm = np.where(nb >= 0, h, np.minimum(_arm(x0, y0, a, axis, sign), h))
            arm = np.maximum(arm, 1e-9 * h)
            arms.append(arm)
            nbrs.append(nb)
        total = arms[0] + arms[1]
        for sign, arm, nb in zip((1, -1), arms, nbrs, strict=True):
            coef = 2.0 / (arm * total)
            diag -= coef
            inner = nb >= 0
            rows.append(np.flatnonzero(inner))
            cols.append(nb[inner])
            vals.append(coef[inner])
            outer = ~inner
            bx = x0[outer] + (sign * arm[outer] if axis == 0 else 0.0)
            by = y0[outer] + (sign * arm[outer] if axis == 1 else 0.0)
            b_rows.append(np.flatnonzero(outer))
            b_phi.append(np.mod(np.arctan2(by, bx), 2.0 * np.pi))
            b_vals.append(coef[outer])
    data = np.concatenate([diag, *vals])
    A = sp.csr_matrix((data, (np.concatenate(rows), np.concatenate(cols))),
                      shape=(grid.n_inside, grid.n_inside))
    rim_phi = np.concatenate(b_phi)
    B = sp.csr_matrix((np.concatenate(b_vals), (np.concatenate(b_rows), np.arange(rim_phi.size))),
                      shape=(grid.n_inside, rim_phi.size))
    A.sort_indices()
    return DiskLaplacian(grid, A, B, rim_phi)


def solve_poisson(grid: ApertureGrid, f: NDArray[np.float64], g=None, solver: str = "direct", *,
                  iterations: int | None = None, tol: float = 1e-10, omega: float | None = None,
                  max_iterations: int = 500_000) -> tuple[NDArray[np.float64], SolveInfo]:
    """Solve Laplacian(delta) = f on the aperture disk with delta = g on the rim.

    Parameters
    ----------
    grid : the aperture grid (D in m, N points across).
    f : right-hand side (1/m), shape (N, N); only points inside the aperture are read.
    g : rim values (m): None for zero, a callable g(phi) of the azimuth (rad), or values at
        the operator's ``rim_phi``. Not accepted by ``fft``.
    solver : one of :data:`SOLVERS`.
    iterations : for ``gauss-seidel`` and ``sor``, a fixed number of sweeps (the paper's 1000);
        None iterates until the relative residual is below ``tol``.
    tol : relative residual target of the iterative solvers.
    omega : SOR factor; None takes the optimum for the disk's lowest mode.
    max_iterations : cap of the iterative solvers when ``iterations`` is None.

    Returns
    -------
    delta : (N, N) in m, NaN outside the aperture.
    info : :class:`SolveInfo`.
    """
    if solver not in SOLVERS:
        raise SolverError(f"unknown solver {solver!r}: choose one of {', '.join(SOLVERS)}")
    check_grid(grid)
    f = np.asarray(f, dtype=np.float64)
    if f.shape != (grid.N, grid.N):
        raise SolverError(f"right-hand side has shape {f.shape}, the grid is {(grid.N, grid.N)}")
    if solver == "fft":
        if g is not None:
            raise SolverError("the fft solver works on the enclosing square and cannot take rim "
                              "values; use direct, multigrid, sor or gauss-seidel")
        return grid.masked(solve_square_dst(f, grid.h)), SolveInfo("fft", note="enclosing square")
    op = disk_laplacian(grid.D, grid.N)
    b = f[grid.mask] - op.boundary_term(g)
    if solver == "direct":
        u = op.lu().solve(b)
        info = SolveInfo("direct", residual=_residual(op.A, u, b))
    elif solver == "multigrid":
        # plain V-cycles: few vector reductions, so no BLAS threads to contend for the cores;
        # BiCGStab on top only if the cycles alone stall
        residuals: list[float] = []
        u = op.amg().solve(b, tol=tol, maxiter=40, residuals=residuals)
        res = _residual(op.A, u, b)
        if res > 10 * tol:
            u = op.amg().solve(b, x0=u, tol=tol, maxiter=100, accel="bicgstab",
                               residuals=residuals)
            res = _residual(op.A, u, b)
        info = SolveInfo("multigrid", len(residuals) - 1, res, res <= 10 * tol)
    else:
        if omega is None:
            omega = optimal_omega(grid) if solver == "sor" else 1.0
        u, info = _relax(op.A, b, omega, iterations, tol, max_iterations)
        info.solver = solver
    out = np.full((grid.N, grid.N), np.nan)
    out[grid.mask] = u
    return out, info


def optimal_omega(grid: ApertureGrid) -> float:
    """SOR factor 2 / (1 + sqrt(1 - rho_J^2)) with rho_J from the disk's lowest Dirichlet mode."""
    rho_jacobi = 1.0 - (J01 / grid.a) ** 2 * grid.h**2 / 4.0
    return 2.0 / (1.0 + np.sqrt(1.0 - rho_jacobi**2))


def _residual(A, u, b) -> float:
    norm = float(np.linalg.norm(b))
    return float(np.linalg.norm(b - A @ u)) / norm if norm > 0 else 0.0


def _relax(A, b, omega: float, iterations: int | None, tol: float, max_iterations: int):
    """Lexicographic Gauss-Seidel / SOR sweeps from zero (pyamg's compiled sweep)."""
    from pyamg.relaxation.relaxation import gauss_seidel, sor

    u = np.zeros_like(b)
    if np.linalg.norm(b) == 0:
        return u, SolveInfo("", 0, 0.0, True, omega)

    def sweep(k: int) -> None:
        if omega == 1.0:
            gauss_seidel(A, u, b, iterations=k)
        else:
            sor(A, u, b, omega, iterations=k)

    if iterations is not None:
        if iterations < 1:
            raise SolverError(f"iterations must be >= 1, got {iterations}")
        sweep(int(iterations))
        res = _residual(A, u, b)
        return u, SolveInfo("", int(iterations), res, res <= tol, omega)
    done, chunk = 0, 50
    res = _residual(A, u, b)
    while res > tol and done < max_iterations:
        sweep(chunk)
        done += chunk
        res = _residual(A, u, b)
    return u, SolveInfo("", done, res, res <= tol, omega)


def solve_square_dst(f: NDArray[np.float64], h: float) -> NDArray[np.float64]:
    """5-point Poisson solve on the whole N x N square, zero one step outside its edge (m).

    A type-I discrete sine transform diagonalises the 5-point Laplacian with these boundary
    values: eigenvalues (2 cos(pi k / (N + 1)) - 2) / h^2, k = 1..N, per direction. Values of
    ``f`` outside the aperture (NaN) count as 0, as in the paper's FFT comparison.
    """
    f = np.where(np.isfinite(f), f, 0.0)
    n = f.shape[0]
    k = np.arange(1, n + 1)
    lam = (2.0 * np.cos(np.pi * k / (n + 1)) - 2.0) / h**2
    spectrum = scipy.fft.dstn(f, type=1)
    return scipy.fft.idstn(spectrum / (lam[:, None] + lam[None, :]), type=1)
