"""The harmonic fill of a grid's missing cells and its transpose, against a dense matrix.

The reference is assembled here cell by cell from the definition (each missing cell equals
the mean of its neighbours inside the grid; known cells keep their values), as a dense
matrix M of the whole map values -> filled values, then solved by numpy: the fill must be M
and its transpose M^T.
"""

import numpy as np
import pytest

from raysim.surface.gridded import HarmonicFill


def _dense_fill_matrix(missing: np.ndarray) -> np.ndarray:
    """M (n, n), n = ny * nx, with filled.ravel() = M @ values.ravel()."""
    ny, nx = missing.shape
    n = ny * nx
    L = np.zeros((n, n))
    for j in range(ny):
        for i in range(nx):
            c = j * nx + i
            for nj, ni in ((j + 1, i), (j - 1, i), (j, i + 1), (j, i - 1)):
                if 0 <= nj < ny and 0 <= ni < nx:
                    L[c, c] += 1.0
                    L[c, nj * nx + ni] -= 1.0
    m = np.flatnonzero(missing.ravel())
    k = np.flatnonzero(~missing.ravel())
    M = np.zeros((n, n))
    M[k, k] = 1.0
    M[np.ix_(m, k)] = -np.linalg.solve(L[np.ix_(m, m)], L[np.ix_(m, k)])
    return M


def _pattern(ny: int, nx: int, seed: int) -> np.ndarray:
    """Outside a disk (the solver's case: corners of the square grid) plus scattered holes,
    some on the grid's outer edge."""
    y, x = np.mgrid[0:ny, 0:nx]
    r = np.hypot((x - (nx - 1) / 2) / (nx / 2), (y - (ny - 1) / 2) / (ny / 2))
    holes = np.random.default_rng(seed).random((ny, nx)) < 0.12
    return (r > 0.9) | holes


@pytest.mark.parametrize("shape, seed", [((9, 11), 0), ((12, 7), 1)])
def test_fill_and_its_transpose_are_the_dense_matrix_and_its_transpose(shape, seed):
    missing = _pattern(*shape, seed)
    assert missing.any() and (~missing).any()
    M = _dense_fill_matrix(missing)
    fill = HarmonicFill(missing)
    rng = np.random.default_rng(seed + 10)
    values = rng.standard_normal(shape)
    gradient = rng.standard_normal(shape)
    np.testing.assert_allclose(fill(values).ravel(), M @ values.ravel(), atol=1e-12)
    back = fill.transpose(gradient)
    np.testing.assert_allclose(back.ravel(), M.T @ gradient.ravel(), atol=1e-12)
    # a missing cell's own input never reaches the fill: its adjoint entry is zero
    assert np.all(back[missing] == 0.0)


def test_transpose_without_missing_cells_is_the_identity():
    values = np.arange(20.0).reshape(4, 5)
    fill = HarmonicFill(np.zeros((4, 5), dtype=bool))
    np.testing.assert_array_equal(fill.transpose(values), values)
