"""Poisson solvers on the aperture disk against known solutions and against each other."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from solver.aperture import ApertureGrid
from solver.errors import SolverError
from solver.poisson import disk_laplacian, solve_poisson, solve_square_dst


def u_exact(x, y):
    return np.exp(0.7 * x) * np.cos(1.3 * y) + x * y**2


def lap_exact(x, y):
    return (0.49 - 1.69) * np.exp(0.7 * x) * np.cos(1.3 * y) + 2 * x


def rim_of(a):
    return lambda phi: u_exact(a * np.cos(phi), a * np.sin(phi))


def test_second_order_convergence_on_the_disk():
    errors = []
    for n in (32, 64, 128):
        grid = ApertureGrid(2.0, n)
        X, Y = grid.XY
        delta, info = solve_poisson(grid, lap_exact(X, Y), rim_of(1.0), "direct")
        assert info.converged
        errors.append(np.nanmax(np.abs(delta - u_exact(X, Y))))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(orders > 1.85), orders
    assert errors[-1] < 2e-5


def test_staircase_boundary_would_be_first_order():
    """The same problem with the rim value put on the last grid point instead of the circle."""
    errors = []
    for n in (32, 64, 128):
        grid = ApertureGrid(2.0, n)
        X, Y = grid.XY
        op = disk_laplacian(2.0, n)
        # rebuild the regular 5-point star: neighbours outside the disk carry the rim value
        # at the neighbour itself (staircase), with arm h
        h = grid.h
        index = -np.ones((n, n), dtype=int)
        index[grid.mask] = np.arange(op.n)
        jj, ii = np.nonzero(grid.mask)
        rows, cols, vals = [np.arange(op.n)], [np.arange(op.n)], [np.full(op.n, -4 / h**2)]
        b = lap_exact(X, Y)[grid.mask].copy()
        for dj, di in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            nj, ni = jj + dj, ii + di
            nb = index[np.clip(nj, 0, n - 1), np.clip(ni, 0, n - 1)]
            inside = (nb >= 0) & (nj >= 0) & (nj < n) & (ni >= 0) & (ni < n)
            rows.append(np.flatnonzero(inside))
            cols.append(nb[inside])
            vals.append(np.full(inside.sum(), 1 / h**2))
            xo, yo = X[0, 0] + ni[~inside] * h, Y[0, 0] + nj[~inside] * h
            phi = np.arctan2(yo, xo)
            b[~inside] -= u_exact(np.cos(phi), np.sin(phi)) / h**2
        A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))))
        u = spla.spsolve(A.tocsc(), b)
        errors.append(np.max(np.abs(u - u_exact(X, Y)[grid.mask])))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(orders < 1.5), orders


def test_converged_solvers_agree_on_the_same_problem():
    grid = ApertureGrid(110.0, 48)
    X, Y = grid.XY
    f = 1e-6 * np.cos(X / 9.0) * np.sin(Y / 13.0 + 0.3)
    g = lambda phi: 1e-4 * np.cos(3 * phi) + 2e-5  # noqa: E731
    ref, _ = solve_poisson(grid, f, g, "direct")
    scale = np.nanmax(np.abs(ref))
    for name in ("multigrid", "sor", "gauss-seidel"):
        got, info = solve_poisson(grid, f, g, name, tol=1e-11)
        assert info.converged, name
        assert np.nanmax(np.abs(got - ref)) < 1e-8 * scale, name
    assert np.array_equal(np.isnan(ref), ~grid.mask)


def test_gauss_seidel_with_the_papers_1000_iterations_is_not_converged():
    grid = ApertureGrid(110.0, 256)
    X, Y = grid.XY
    f = 1e-6 * np.cos(np.hypot(X, Y) / 9.0)
    ref, _ = solve_poisson(grid, f, None, "direct")
    got, info = solve_poisson(grid, f, None, "gauss-seidel", iterations=1000)
    assert info.iterations == 1000
    assert not info.converged and info.residual > 1e-3
    assert np.nanmax(np.abs(got - ref)) > 0.05 * np.nanmax(np.abs(ref))


def test_fft_solves_the_enclosing_square_with_zero_edges():
    n, h = 40, 0.7
    rng = np.random.default_rng(3)
    f = rng.standard_normal((n, n))
    one = sp.diags([np.ones(n - 1), -2 * np.ones(n), np.ones(n - 1)], [-1, 0, 1]) / h**2
    lap = sp.kronsum(one, one).tocsc()
    expected = spla.spsolve(lap, f.ravel()).reshape(n, n)
    np.testing.assert_allclose(solve_square_dst(f, h), expected, rtol=1e-10, atol=1e-12)


def test_fft_differs_from_the_disk_problem():
    grid = ApertureGrid(110.0, 64)
    f = np.full((64, 64), 1e-6)
    disk, _ = solve_poisson(grid, f, None, "direct")
    square, info = solve_poisson(grid, f, None, "fft")
    assert info.note == "enclosing square"
    assert np.nanmax(np.abs(square - disk)) > 0.1 * np.nanmax(np.abs(disk))


def test_harmonic_rim_values_give_the_harmonic_solution():
    grid = ApertureGrid(2.0, 64)
    X, Y = grid.XY
    delta, _ = solve_poisson(grid, np.zeros((64, 64)), lambda phi: np.cos(2 * phi))
    np.testing.assert_allclose(delta[grid.mask], (X**2 - Y**2)[grid.mask], atol=2e-4)


def test_bad_requests_raise_solver_errors():
    grid = ApertureGrid(110.0, 32)
    with pytest.raises(SolverError, match="unknown solver"):
        solve_poisson(grid, np.zeros((32, 32)), None, "jacobi")
    with pytest.raises(SolverError, match="N must be"):
        solve_poisson(ApertureGrid(110.0, 8), np.zeros((8, 8)))
    with pytest.raises(SolverError, match="rim values"):
        solve_poisson(grid, np.zeros((32, 32)), lambda p: p, "fft")
    with pytest.raises(SolverError, match="shape"):
        solve_poisson(grid, np.zeros((16, 16)))
