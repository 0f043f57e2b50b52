"""From a surface map to actuator commands, the residual they leave and the gain they buy.

Frame: aperture plane (x, y) (m), the map ``delta`` along z (m) on an
:class:`~raysim.maps.aperture.ApertureGrid`. Sign: a positive command moves the surface along +z
(away from the vertex, toward the focus); the commands c minimise the area-weighted
sum over the panel points of (delta' + A c)^2, where delta' is the map with the ``remove`` terms
(piston, tilt, focus: left to pointing and subreflector focus) fitted and taken off, and A the
influence matrix of :mod:`solver.actuators` (each panel moved as the shape its support points
impose). The predicted surface after the correction is delta' + A c. With stroke ranges the
problem is bounded least squares (:func:`scipy.optimize.lsq_linear`), the ``remove`` terms
fitted jointly as free columns (the commands' bounds may leave some of them, which pointing
takes up): after = delta' + A c + G t.

Gain: the Ruze aperture efficiency exp(-(4 pi sigma / lambda)^2), sigma the area-weighted RMS
over the panels (m) of the half-path-length error dz / (1 + rho^2 / (4 F^2)) (Ruze 1966), the
``remove`` terms taken off it again; the axial RMS where F is unknown. Zernike content:
least-squares Noll coefficients (m, each term's RMS over the disk) of
:class:`raysim.surface.deformation.Zernike` terms up to a radial order.
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
from solver.fit import _design, remove_terms


@dataclass
class Correction:
    """Commands (m, one per actuator), the maps before (terms removed) and after (m, (N, N), NaN
    off the aperture), their RMS (m), the command standard deviations (m) when known and, when
    the focal length is known, the RMS (m) of the half-path-length error before and after."""

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
    path_rms_before: float | None = None
    path_rms_after: float | None = None


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
            remove: tuple[str, ...] = (), delta_std: NDArray[np.float64] | None = None,
            focal_length: float | None = None) -> Correction:
    """Least-squares commands for the map ``delta`` (m) and what they leave (see the module).
    ``focal_length`` (m): the dish's F, for the half-path-length RMS Ruze's law takes
    (:func:`half_path_rms`); None leaves it out."""
    before, removed = remove_terms(grid, np.asarray(delta, dtype=np.float64), remove)
    ids = panel_ids(grid, before, layout)
    A = influence_matrix(grid, ids, layout, actuators)
    held = np.asarray(abs(A).sum(axis=0)).ravel() > 0
    notes = []
    if not held.all():
        notes.append(f"{int((~held).sum())} actuators touch no map point: commanded 0")
    free = held & _unlocked(actuators, held, notes)
    on = ids.ravel() >= 0
    d = before.ravel()[on]
    Af = A[:, free]
    # the free actuators' normal matrix A^T A, decomposed once for the note on what the map
    # leaves undetermined and for the least-norm solve
    w, V = np.linalg.eigh((Af.T @ Af).toarray())
    kept = w > max(w.max(initial=0.0), 0.0) * NULL_SHARE
    notes += _undetermined_note(V[:, ~kept], np.flatnonzero(free), actuators)
    commands = np.zeros(actuators.n_actuators)
    clipped = 0
    extra = np.zeros(on.sum())
    if actuators.ranges is None:
        Vk = V[:, kept]
        commands[free] = Vk @ ((Vk.T @ -(Af.T @ d)) / w[kept])
    elif free.any():
        G, names = _term_columns(grid, ids, remove)
        commands[free], coef, clipped = _bounded_fit(Af, d, actuators.ranges[free], G)
        extra = G @ coef  # the removed terms, refitted jointly with the bounded commands
        removed = {k: v + (float(coef[names.index(k)]) if k in names else 0.0)
                   for k, v in removed.items()}
    after_flat = np.full(before.size, np.nan)
    after_flat[on] = d + A @ commands + extra
    # points in the gaps between panels are no surface: NaN after, and left out of both RMS
    after = grid.masked(after_flat.reshape(before.shape))
    std = None
    if delta_std is not None and np.isfinite(delta_std).any():
        std = np.zeros(actuators.n_actuators)  # locked actuators do not move: exactly 0
        std[free] = command_std(Af, np.asarray(delta_std, dtype=np.float64).ravel()[on])
    on_panels = np.where(ids >= 0, before, np.nan)
    result = Correction(commands, before, after, rms(on_panels), rms(after), removed,
                        within_panel_rms(grid, before, ids), std, clipped, notes)
    if focal_length is not None:
        result.path_rms_before = half_path_rms(grid, on_panels, focal_length, remove)
        result.path_rms_after = half_path_rms(grid, after, focal_length, remove)
    return result


def _unlocked(actuators: ActuatorLayout, held: NDArray[np.bool_], notes: list[str]) -> NDArray[np.bool_]:
    """Which actuators may move: all without ranges; else those whose range (m) is not one
    value (min_m = max_m = 0: locked, counted in ``notes``). A range excluding 0 is refused."""
    n = actuators.n_actuators
    if actuators.ranges is None:
        return np.ones(n, dtype=bool)
    lo, hi = actuators.ranges[:, 0], actuators.ranges[:, 1]
    bad = np.flatnonzero(held & ((lo > 0) | (hi < 0)))
    if bad.size:
        a = int(bad[0])
        raise ActuatorError(f"actuator {actuators.ids[a]}: its range [{lo[a]:g}, {hi[a]:g}] m "
                            "excludes 0 (min_m > 0 or max_m < 0)")
    locked = held & (lo >= hi)
    if locked.any():
        notes.append(f"{int(locked.sum())} actuators locked (min_m = max_m = 0): commanded 0")
    return ~locked


#: eigenvalues of A^T A under this share of the largest are its null space: commands the map
#: does not determine
NULL_SHARE = 1e-10


def _undetermined_note(null: NDArray[np.float64], columns: NDArray[np.int64],
                       actuators: ActuatorLayout) -> list[str]:
    """A note when the map does not fix every command: actuators (``columns`` of the layout)
    with a share in ``null``, the null space of A^T A (a panel with fewer map points than
    actuators, or points on a line), get the minimum-norm choice; the panels they hold are
    counted."""
    if null.shape[1] == 0:
        return []
    loose = columns[np.linalg.norm(null, axis=1) > 1e-6]
    loose_set = set(loose.tolist())
    panels = {p for p, sup in enumerate(actuators.supports) if any(a in loose_set for a, _, _ in sup)}
    return [f"{len(loose)} actuators on {len(panels)} panels are not determined by the map (too "
            "few map points on their panels): their commands are the least-norm choice"]


def _term_columns(grid, ids: NDArray[np.int64], terms) -> tuple[NDArray[np.float64], list[str]]:
    """Columns (points on the panels, k) of the ``terms`` (piston, tilt, focus; see
    :mod:`solver.fit`) at the grid points with ``ids`` >= 0, and the coefficient names."""
    X, Y = grid.XY
    on = ids.ravel() >= 0
    if not terms:
        return np.zeros((int(on.sum()), 0)), []
    return _design(X.ravel()[on], Y.ravel()[on], terms)


def _bounded_fit(A: sp.csr_matrix, d: NDArray[np.float64], ranges: NDArray[np.float64],
                 G: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    """(commands (m), term coefficients, how many commands sit at a limit) of :func:`_bounded`
    with the stroke ``ranges`` (m, (actuators, 2))."""
    lo, hi = ranges[:, 0], ranges[:, 1]
    c, t = _bounded(A, d, lo, hi, G)
    clipped = int(np.sum((c <= lo + 1e-15) & np.isfinite(lo)) + np.sum((c >= hi - 1e-15) & np.isfinite(hi)))
    return c, t, clipped


def _bounded(A: sp.csr_matrix, d: NDArray[np.float64], lo, hi,
             G: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """argmin ||A c + G t + d|| over lo <= c <= hi (m) and free coefficients t of the columns
    ``G`` (the removed terms: pointing takes them whatever the commands leave); returns (c, t).
    With Q an orthonormal basis of G the problem in c is ||(I - Q Q^T)(A c + d)||, whose normal
    matrix N = V diag(w) V^T gives the small equivalent ||diag(sqrt w) V^T c - y|| (BVLS on
    (actuators x actuators), never the dense points x actuators matrix; singular N allowed)."""
    Q, _ = np.linalg.qr(G) if G.shape[1] else (np.zeros((len(d), 0)), None)
    QA = np.asarray((A.T @ Q).T)  # (k, actuators)
    N = (A.T @ A).toarray() - QA.T @ QA
    b = A.T @ d - QA.T @ (Q.T @ d)
    w, V = np.linalg.eigh(N)
    keep = w > max(w.max(), 0.0) * 1e-13
    root = np.sqrt(w[keep])
    R = root[:, None] * V[:, keep].T
    y = -(V[:, keep].T @ b) / root
    c = lsq_linear(R, y, bounds=(lo, hi), method="bvls", tol=1e-14).x
    t = np.linalg.lstsq(G, -(A @ c + d), rcond=None)[0] if G.shape[1] else np.zeros(0)
    return c, t


def command_std(A: sp.csr_matrix, point_std: NDArray[np.float64]) -> NDArray[np.float64]:
    """Standard deviation (m) of each unbounded least-squares command from independent map
    errors of standard deviation ``point_std`` (m) at the rows of ``A`` (the free actuators'
    columns: a locked one is no unknown): diag(P A^T diag(s^2) A P), P the pseudo-inverse of
    A^T A."""
    s = np.where(np.isfinite(point_std), point_std, 0.0)
    P = np.linalg.pinv((A.T @ A).toarray())
    G = (A.T @ sp.diags(s * s) @ A).toarray()
    return np.sqrt(np.maximum(np.einsum("ij,jk,ki->i", P, G, P), 0.0))


def half_path_rms(grid, axial: NDArray[np.float64], focal_length: float, remove=()) -> float:
    """RMS (m) of the half-path-length error Ruze's law takes (Ruze 1966, Proc. IEEE 54(4)) of
    an axial surface error ``axial`` (m, NaN off the panels) of a paraboloid of focal length F
    (m): dz / (1 + rho^2 / (4 F^2)) = dz cos^2(theta / 2) at radius rho, with the ``remove``
    terms fitted to it and taken off again (what pointing and focus take up is in the path)."""
    X, Y = grid.XY
    path = axial / (1.0 + (X * X + Y * Y) / (4.0 * focal_length**2))
    return rms(remove_terms(grid, path, remove)[0]) if remove else rms(path)


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
