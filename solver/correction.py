"""From a surface map to actuator commands, the residual they leave and the gain they buy.

Frame: aperture plane (x, y) (m), the map ``delta`` along z (m) on an
:class:`~raysim.maps.aperture.ApertureGrid`. Sign: a positive command moves the surface along +z
(away from the vertex, toward the focus); the commands c minimise the area-weighted
sum over the panel points of (delta' + A c)^2, where delta' is the map with the ``remove`` terms
(piston, tilt, focus: left to pointing and subreflector focus) fitted and taken off, and A the
influence matrix of :mod:`solver.actuators` (each panel moved as the shape its support points
impose). The predicted surface after the correction is delta' + A c. With stroke ranges the
problem is bounded least squares (:func:`scipy.optimize.lsq_linear`).

Gain: the Ruze aperture efficiency exp(-(4 pi sigma / lambda)^2), sigma the area-weighted RMS
over the aperture (m). Zernike content: least-squares Noll coefficients (m, each term's RMS over
the disk) of :class:`raysim.surface.deformation.Zernike` terms up to a radial order.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.optimize import lsq_linear

from raysim.constants import C0
from raysim.surface.deformation import Zernike, noll_norm
from solver.actuators import ActuatorError, ActuatorLayout, shape_functions
from solver.fit import remove_terms


@dataclass
class Correction:
    """Commands (m, one per actuator), the maps before (terms removed) and after (m, (N, N), NaN
    off the aperture), their RMS (m) and the command standard deviations (m) when known."""

    commands: NDArray[np.float64]
    before: NDArray[np.float64]
    after: NDArray[np.float64]
    rms_before: float
    rms_after: float
    removed: dict[str, float]
    within_panel_rms: float
    command_std: NDArray[np.float64] | None = None
    clipped: int = 0
    notes: list[str] = field(default_factory=list)


def influence_matrix(grid, ids: NDArray[np.int64], layout, actuators: ActuatorLayout) -> sp.csr_matrix:
    """Sparse (n points, n actuators) matrix: the surface displacement (m) at the grid points
    flagged by panel ``ids`` (ids >= 0, flattened order) per metre of each actuator's command."""
    X, Y = grid.XY
    xs, ys, pid = X.ravel(), Y.ravel(), ids.ravel()
    rows_of = np.flatnonzero(pid >= 0)
    pos = np.full(pid.shape, -1)
    pos[rows_of] = np.arange(len(rows_of))
    r_idx, c_idx, vals = [], [], []
    for panel, sup in enumerate(actuators.supports):
        on = np.flatnonzero(pid == panel)
        if len(on) == 0:
            continue
        W = shape_functions(layout, panel, sup, xs[on], ys[on])
        for k, (a, _, _) in enumerate(sup):
            r_idx.append(pos[on])
            c_idx.append(np.full(len(on), a))
            vals.append(W[:, k])
    shape = (len(rows_of), actuators.n_actuators)
    if not vals:
        return sp.csr_matrix(shape)
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(r_idx), np.concatenate(c_idx))),
                         shape=shape)


def panel_ids(grid, delta: NDArray[np.float64], layout) -> NDArray[np.int64]:
    """Panel id of each grid point with a finite map value inside the aperture, else -1."""
    X, Y = grid.XY
    return np.where(grid.mask & np.isfinite(delta), layout.panel_at(X, Y), -1)


def rms(values: NDArray[np.float64]) -> float:
    """RMS (m) over the finite values (equal cells: area-weighted)."""
    v = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(v * v))) if v.size else float("nan")


def correct(grid, delta: NDArray[np.float64], layout, actuators: ActuatorLayout,
            remove: tuple[str, ...] = (), delta_std: NDArray[np.float64] | None = None) -> Correction:
    """Least-squares commands for the map ``delta`` (m) and what they leave (see the module)."""
    before, removed = remove_terms(grid, np.asarray(delta, dtype=np.float64), remove)
    ids = panel_ids(grid, before, layout)
    A = influence_matrix(grid, ids, layout, actuators)
    held = np.asarray(abs(A).sum(axis=0)).ravel() > 0
    notes = []
    if not held.all():
        notes.append(f"{int((~held).sum())} actuators touch no map point: commanded 0")
    on = ids.ravel() >= 0
    d = before.ravel()[on]
    Ah = A[:, held]
    clipped = 0
    commands = np.zeros(actuators.n_actuators)
    if actuators.ranges is None:
        N = (Ah.T @ Ah).toarray()
        sol, *_ = np.linalg.lstsq(N, -(Ah.T @ d), rcond=None)
    else:
        lo, hi = actuators.ranges[held, 0], actuators.ranges[held, 1]
        if np.any(lo > 0) or np.any(hi < 0):
            raise ActuatorError("an actuator's range excludes 0 (min_m > 0 or max_m < 0)")
        # a range that includes 0 and is one value is a locked actuator: it stays at 0
        free = lo < hi
        if not free.all():
            notes.append(f"{int((~free).sum())} actuators locked (min_m = max_m = 0): commanded 0")
        sol = np.zeros(len(lo))
        if free.any():
            lo, hi = lo[free], hi[free]
            sol[free] = moved = _bounded(Ah[:, free], d, lo, hi)
            clipped = int(np.sum((moved <= lo + 1e-15) & np.isfinite(lo))
                          + np.sum((moved >= hi - 1e-15) & np.isfinite(hi)))
    commands[held] = sol
    after_flat = np.full(before.size, np.nan)
    after_flat[on] = d + A @ commands
    # points in the gaps between panels are no surface: NaN after, and left out of both RMS
    after = grid.masked(after_flat.reshape(before.shape))
    std = None
    if delta_std is not None and np.isfinite(delta_std).any():
        std = np.zeros(actuators.n_actuators)
        std[held] = command_std(Ah, np.asarray(delta_std, dtype=np.float64).ravel()[on])
    on_panels = np.where(ids >= 0, before, np.nan)
    return Correction(commands, before, after, rms(on_panels), rms(after), removed,
                      within_panel_rms(grid, before, ids), std, clipped, notes)


def _bounded(A: sp.csr_matrix, d: NDArray[np.float64], lo, hi) -> NDArray[np.float64]:
    """argmin ||A c + d|| with lo <= c <= hi (BVLS). With A^T A = L L^T (Cholesky) the problem
    is the small one ||L^T c + L^-1 A^T d|| (the same objective less a constant); the dense
    (points x actuators) problem only when A^T A is singular."""
    N = (A.T @ A).toarray()
    try:
        L = np.linalg.cholesky(N)
    except np.linalg.LinAlgError:
        return lsq_linear(A.toarray(), -d, bounds=(lo, hi), method="bvls", tol=1e-14).x
    rhs = np.linalg.solve(L, A.T @ d)
    return lsq_linear(L.T, -rhs, bounds=(lo, hi), method="bvls", tol=1e-14).x


def command_std(A: sp.csr_matrix, point_std: NDArray[np.float64]) -> NDArray[np.float64]:
    """Standard deviation (m) of each unbounded least-squares command from independent map
    errors of standard deviation ``point_std`` (m) at the rows of ``A``:
    diag(P A^T diag(s^2) A P), P the pseudo-inverse of A^T A."""
    s = np.where(np.isfinite(point_std), point_std, 0.0)
    P = np.linalg.pinv((A.T @ A).toarray())
    G = (A.T @ sp.diags(s * s) @ A).toarray()
    return np.sqrt(np.maximum(np.einsum("ij,jk,ki->i", P, G, P), 0.0))


def within_panel_rms(grid, delta: NDArray[np.float64], ids: NDArray[np.int64]) -> float:
    """RMS (m) of what no rigid panel motion reaches: over every panel, the map minus its own
    best-fit plane (piston and two tilts); the floor of any actuator correction that moves the
    panels as rigid bodies (a bilinear corner layout can reach slightly more: the twist)."""
    X, Y = grid.XY
    res = []
    for panel in np.unique(ids[ids >= 0]):
        on = ids == panel
        if on.sum() < 3:
            continue
        design = np.stack([np.ones(on.sum()), X[on], Y[on]], axis=-1)
        coef, *_ = np.linalg.lstsq(design, delta[on], rcond=None)
        res.append(delta[on] - design @ coef)
    return rms(np.concatenate(res)) if res else float("nan")


def ruze(sigma_m: float, frequency_hz) -> NDArray[np.float64]:
    """Ruze aperture efficiency exp(-(4 pi sigma / lambda)^2) at each frequency (Hz)."""
    lam = C0 / np.asarray(frequency_hz, dtype=np.float64)
    return np.exp(-((4.0 * np.pi * sigma_m / lam) ** 2))


def noll_to_nm(j: int) -> tuple[int, int]:
    """Noll index j >= 1 to (n, m): m >= 0 the cos term, m < 0 the sin term (Noll 1976: even j
    cos, odd j sin for m != 0)."""
    if j < 1:
        raise ValueError("Noll indices start at 1")
    n = 0
    while (n + 1) * (n + 2) // 2 < j:
        n += 1
    k = j - n * (n + 1) // 2 - 1  # 0-based position within the order
    m = 2 * ((k + 1) // 2) if n % 2 == 0 else 2 * (k // 2) + 1
    if m != 0 and j % 2:
        m = -m
    return n, m


def zernike_fit(grid, delta: NDArray[np.float64], order: int) -> list[tuple[int, int, int, float]]:
    """Noll coefficients (j, n, m, c in m, c the term's RMS over the disk) of ``delta`` (m) for
    every term of radial order <= ``order``, fitted together by least squares over the finite
    aperture points."""
    count = (order + 1) * (order + 2) // 2
    nm = [noll_to_nm(j) for j in range(1, count + 1)]
    X, Y = grid.XY
    use = grid.mask & np.isfinite(delta)
    z = Zernike(tuple((n, m, 1.0) for n, m in nm), grid.a)
    cols = [R * ang * noll_norm(n, m)
            for (n, m), (R, ang, _, _) in zip(nm, z.factors(X[use], Y[use], False), strict=True)]
    coef, *_ = np.linalg.lstsq(np.stack(cols, axis=-1), delta[use], rcond=None)
    return [(j + 1, n, m, float(c)) for j, ((n, m), c) in enumerate(zip(nm, coef, strict=True))]


def displacement(layout, actuators: ActuatorLayout, commands: NDArray[np.float64], x, y) -> NDArray:
    """Surface displacement (m) along z at aperture points (x, y) (m) when the actuators move by
    ``commands`` (m): each panel takes its support points' shape; 0 in gaps and off the dish."""
    xs, ys = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    out = np.zeros(xs.shape)
    ids = layout.panel_at(xs, ys)
    for panel in np.unique(ids[ids >= 0]):
        on = ids == panel
        sup = actuators.supports[panel]
        W = shape_functions(layout, int(panel), sup, xs[on], ys[on])
        out[on] = W @ np.asarray(commands)[[a for a, _, _ in sup]]
    return out
