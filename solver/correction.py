"""From a surface map to actuator commands, the residual they leave and the gain they buy.

Frame: aperture plane (x, y) (m), the map ``delta`` along z (m) on an
:class:`~raysim.maps.aperture.ApertureGrid`. Sign: a positive command moves the surface along +z
(away from the vertex, toward the focus); the commands c and the coefficients t of the
``remove`` terms' columns G (piston, tilt, focus: left to pointing and subreflector focus)
minimise the area-weighted sum over the panel points of (delta' + A c + G t)^2, where delta'
is the map with those terms fitted over the panels and taken off, and A the influence matrix
of :mod:`solver.actuators` (each panel moved as the shape its support points impose). The
predicted surface after the correction is delta' + A c + G t: what the commands leave of a
removed term, pointing takes up. Without stroke ranges c is the least-norm minimiser (the
commands the map does not fix, and those that would only make a removed term, are 0); with
them the problem is bounded least squares (:func:`scipy.optimize.lsq_linear`).

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
from raysim.errors import SurfaceMapError
from raysim.scene.deformations import MAX_DEFORMATION_M
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


def draws_command_std(grid, ids: NDArray[np.int64], fit: JointFit, remove: tuple[str, ...],
                      noise_draws: NDArray[np.float64]) -> NDArray[np.float64]:
    """Std (m) of each of ``fit``'s unbounded commands over the map's noise ``noise_draws``
    ((draws, N, N), m): each draw through the same term removal and least squares as the map.
    The inversion's noise lies in a few smooth shapes across the dish, which a panel's points
    share: the independent-point propagation (:meth:`JointFit.command_std`) gave 0.53 um where
    the commands of noisy maps scattered by 4 to 7 um. An actuator with a point of unknown
    spread (NaN in the draws) on its panels gets NaN."""
    on = ids.ravel() >= 0
    commands = []
    for draw in np.asarray(noise_draws, dtype=np.float64):
        kept, _ = remove_terms(grid, np.where(ids >= 0, draw, np.nan), remove)
        commands.append(fit.least_norm(np.nan_to_num(kept.ravel()[on])))
    std = np.std(np.stack(commands), axis=0, ddof=1)
    unknown_points = ~np.isfinite(np.asarray(noise_draws[0], dtype=np.float64).ravel()[on])
    unknown = np.asarray(abs(fit.A[unknown_points]).sum(axis=0)).ravel() > 0
    return np.where(unknown, np.nan, std)


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
            focal_length: float | None = None,
            noise_draws: NDArray[np.float64] | None = None) -> Correction:
    """Least-squares commands for the map ``delta`` (m) and what they leave (see the module).
    ``focal_length`` (m): the dish's F, for the half-path-length RMS Ruze's law takes
    (:func:`half_path_rms`); None leaves it out. The commands' std comes from ``noise_draws``
    ((draws, N, N), m: the inversion's Monte Carlo draws of the map's noise) where given, each
    draw taken through the fit; else from ``delta_std`` with the points independent. A map
    departing by more than :data:`MAX_DEPARTURE_M` once the ``remove`` terms are off is refused
    (:class:`~raysim.errors.SurfaceMapError`: no surface error, a unit mistake)."""
    delta = np.asarray(delta, dtype=np.float64)
    ids = panel_ids(grid, delta, layout)
    if not np.any(ids >= 0):
        raise ActuatorError("no point of the map lies on a panel: nothing the actuators reach")
    # the terms are fitted over the panels alone: a value in a gap is no surface
    before, removed = remove_terms(grid, np.where(ids >= 0, delta, np.nan), remove)
    scale = float(np.nanmax(np.abs(before))) if np.isfinite(before).any() else 0.0
    if scale > MAX_DEPARTURE_M:
        raise SurfaceMapError(
            f"the map departs by up to {scale:.3g} m from the dish ({', '.join(remove) or 'no terms'}"
            f" removed), more than the {MAX_DEPARTURE_M:g} m beyond which no reflector's surface "
            "error or actuator's travel goes: is the deformation in metres? (a map in um stored "
            "as m is 1e6 times too large)")
    A = influence_matrix(grid, ids, layout, actuators)
    held = np.asarray(abs(A).sum(axis=0)).ravel() > 0
    notes = []
    if not held.all():
        notes.append(f"{int((~held).sum())} actuators touch no map point: commanded 0")
    free = held & _unlocked(actuators, held, notes)
    on = ids.ravel() >= 0
    d = before.ravel()[on]
    Af = A[:, free]
    G, names = term_columns(grid, ids, remove)
    fit = JointFit(Af, G)
    notes += _undetermined_note(fit.undetermined(), np.flatnonzero(free), actuators)
    commands = np.zeros(actuators.n_actuators)
    clipped = 0
    if actuators.ranges is None:
        commands[free] = fit.least_norm(d)
    elif free.any():
        commands[free], clipped = fit.bounded(d, actuators.ranges[free])
    # the removed terms refitted with the commands: pointing (and focus) takes up what they leave
    coef = fit.terms(commands[free], d)
    removed = {k: v + (float(coef[names.index(k)]) if k in names else 0.0)
               for k, v in removed.items()}
    after_flat = np.full(before.size, np.nan)
    after_flat[on] = d + A @ commands + G @ coef
    # points in the gaps between panels are no surface: NaN after, and left out of both RMS
    after = grid.masked(after_flat.reshape(before.shape))
    std = None
    if noise_draws is not None and len(noise_draws) > 1:
        std = np.zeros(actuators.n_actuators)  # locked actuators do not move: exactly 0
        std[free] = draws_command_std(grid, ids, fit, remove, noise_draws)
    elif delta_std is not None and np.isfinite(delta_std).any():
        std = np.zeros(actuators.n_actuators)
        std[free] = fit.command_std(np.asarray(delta_std, dtype=np.float64).ravel()[on])
    if scale > SUSPECT_SHARE * grid.D:
        notes.append(f"the map departs by up to {scale:.3g} m on a {grid.D:g} m dish: is it in "
                     "metres? (commands follow it as it is)")
    result = Correction(commands, before, after, rms(before), rms(after), removed,
                        within_panel_rms(grid, before, ids), std, clipped, notes)
    if focal_length is not None:
        result.path_rms_before = half_path_rms(grid, before, focal_length, remove)
        result.path_rms_after = half_path_rms(grid, after, focal_length, remove)
    return result


#: a map departing by more than this share of the diameter (and at most MAX_DEPARTURE_M) may be
#: no surface error (a map in mm labelled m): said in the notes
SUSPECT_SHARE = 1e-3
#: a map departing by more than this (m) from the dish, the removed terms taken off, is refused:
#: the 10 cm a scene allows a deformation (raysim.scene.deformations), beyond any reflector's
#: surface error and the travel of any panel actuator or adjustment screw (millimetres to a few
#: centimetres). A map in um stored as m departs by its error times 1e6: a 189 um bump gave
#: 189 m and commands of -167 m, written with exit status 0 beside a note
MAX_DEPARTURE_M = MAX_DEFORMATION_M


class JointFit:
    """The commands c (m) and the removed terms' coefficients t that minimise
    ||A c + G t + d|| over the panel points, for maps d (m): with Q an orthonormal basis of G's columns, c
    minimises ||(I - Q Q^T)(A c + d)||, whose normal matrix N = A^T (I - Q Q^T) A is small
    (actuators x actuators). N is decomposed once, with its columns scaled to unit diagonal
    of A^T A, so that one panel of ill-conditioned supports does not set the threshold for
    every other (its eigenvalues span many orders against a plain threshold on the largest).
    """

    def __init__(self, A: sp.csr_matrix, G: NDArray[np.float64]):
        self.A, self.G = A, G
        Q = np.linalg.qr(G)[0] if G.shape[1] else np.zeros((A.shape[0], 0))
        QA = np.asarray((A.T @ Q).T)  # (k, actuators)
        self.Q, self.QA = Q, QA
        AtA = (A.T @ A).toarray()
        self.AtA = AtA
        diag = np.diag(AtA)
        self.scale = 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0))
        self.w, self.V, self.kept = _scaled_eigh(AtA - QA.T @ QA, self.scale)
        self.null = self._null(self.V, self.kept)  # N's null space, in commands

    def _b(self, d: NDArray[np.float64]) -> NDArray[np.float64]:
        """A^T (I - Q Q^T) d."""
        return self.A.T @ d - self.QA.T @ (self.Q.T @ d)

    def _null(self, V: NDArray[np.float64], kept: NDArray[np.bool_]) -> NDArray[np.float64]:
        """An orthonormal basis (actuators, m) of the null directions, in commands."""
        if kept.all():
            return np.zeros((len(self.scale), 0))
        return np.linalg.qr(self.scale[:, None] * V[:, ~kept])[0]

    def undetermined(self) -> NDArray[np.float64]:
        """The null space of A^T A: the commands the map does not fix (those that only make
        a removed term are fixed: the terms take them)."""
        if self.G.shape[1] == 0:
            return self.null
        _, V, kept = _scaled_eigh(self.AtA, self.scale)
        return self._null(V, kept)

    def least_norm(self, d: NDArray[np.float64]) -> NDArray[np.float64]:
        """The unbounded minimiser of least norm (m): a minimiser from the scaled
        decomposition, its part along N's null space taken off."""
        Vk, s = self.V[:, self.kept], self.scale
        c = s * (Vk @ ((Vk.T @ (s * -self._b(d))) / self.w[self.kept]))
        return c - self.null @ (self.null.T @ c)

    def bounded(self, d: NDArray[np.float64], ranges: NDArray[np.float64]
                ) -> tuple[NDArray[np.float64], int]:
        """The minimiser within the stroke ``ranges`` (m, (actuators, 2)) and how many commands
        sit at a limit: BVLS on the small equivalent ||diag(sqrt w) V^T u - y||, c = S u (never
        the dense points x actuators matrix; a singular N allowed)."""
        lo, hi = ranges[:, 0], ranges[:, 1]
        s, keep = self.scale, self.kept
        root = np.sqrt(self.w[keep])
        R = root[:, None] * self.V[:, keep].T
        y = -(self.V[:, keep].T @ (s * self._b(d))) / root
        c = s * lsq_linear(R, y, bounds=(lo / s, hi / s), method="bvls", tol=1e-14).x
        c = np.clip(c, lo, hi)  # the scaling's rounding must not step past a limit
        clipped = int(np.sum((c <= lo + 1e-15) & np.isfinite(lo))
                      + np.sum((c >= hi - 1e-15) & np.isfinite(hi)))
        return c, clipped

    def terms(self, c: NDArray[np.float64], d: NDArray[np.float64]) -> NDArray[np.float64]:
        """The removed terms' coefficients t for the commands ``c`` on the map ``d``: least
        squares of the rest."""
        if self.G.shape[1] == 0:
            return np.zeros(0)
        return np.linalg.lstsq(self.G, -(self.A @ c + d), rcond=None)[0]

    def command_std(self, point_std: NDArray[np.float64]) -> NDArray[np.float64]:
        """Standard deviation (m) of each unbounded command from independent map errors of
        standard deviation ``point_std`` (m) at the panel points, through the fit as it is
        (the terms' removal included): c = -N^+ A^T P e with P = I - Q Q^T, so
        Cov c = N^+ A^T P S P A N^+, S = diag(std^2). An actuator with a point of unknown
        spread (NaN) on its panels gets NaN. N^+ is the operator :meth:`least_norm` applies:
        the scaled inverse on N's range, its null part taken off."""
        known = np.isfinite(point_std)
        v = np.where(known, point_std, 0.0) ** 2
        A, Q, QA = self.A, self.Q, self.QA
        ASQ = np.asarray(A.T @ (v[:, None] * Q))  # (actuators, k)
        M = ((A.T @ sp.diags(v) @ A).toarray() - ASQ @ QA - QA.T @ ASQ.T
             + QA.T @ ((Q.T * v) @ Q) @ QA)
        Vk, s = self.V[:, self.kept], self.scale
        Np = (s[:, None] * Vk / self.w[self.kept]) @ (Vk.T * s)
        Np -= self.null @ (self.null.T @ Np)
        std = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", Np, M, Np), 0.0))
        unknown = np.asarray(abs(A[~known]).sum(axis=0)).ravel() > 0
        return np.where(unknown, np.nan, std)


def _scaled_eigh(M: NDArray[np.float64], scale: NDArray[np.float64]
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Eigenvalues and vectors of S M S (S = diag(scale)) and which lie above the null share."""
    w, V = np.linalg.eigh(scale[:, None] * M * scale[None, :])
    return w, V, w > max(w.max(initial=0.0), 0.0) * NULL_SHARE


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


def term_columns(grid, ids: NDArray[np.int64], terms) -> tuple[NDArray[np.float64], list[str]]:
    """Columns (points on the panels, k) of the ``terms`` (piston, tilt, focus; see
    :mod:`solver.fit`) at the grid points with ``ids`` >= 0, and the coefficient names."""
    X, Y = grid.XY
    on = ids.ravel() >= 0
    if not terms:
        return np.zeros((int(on.sum()), 0)), []
    return _design(X.ravel()[on], Y.ravel()[on], terms)


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
