"""The error budget of a scan plan: the deformation RMS the readings' noise leaves, by mode.

Frame and units (docs/physics.md): aperture radius r (m), a = D/2, delta in m, noise in dB
per reading, FA dimensionless. No Monte Carlo: the linear inversion delta = Laplacian^-1(FA / G)
(Dirichlet on the disk) is written in the disk's Dirichlet eigenfunctions

    phi_mn(r, phi) = N_mn J_m(j_mn r / a) (cos m phi, sin m phi),   Laplacian phi = -(j_mn/a)^2 phi,

normalised to unit norm over the disk, so that <delta, phi_k> = -<FA / G, phi_k> / lambda_k and
E ||delta||^2 = sum_k var(<FA / G, phi_k>) / lambda_k^2 (Parseval, no cross terms). Each sphere
cell c is one independent reading (averaged over K readings) of relative std
sigma = (ln 10 / 10) s_dB / sqrt(K); FA = I_ideal / I - 1 moves by -sigma, constant over the
cell's aperture footprint of area A_c (the ideal GO mapping r = 2F tan(theta/2)), so
var(<FA / G, g>) = sigma^2 sum_c A_c^2 g(x_c)^2 / G_c^2. The cells form rings, and the sum over
a ring of cos^2(m phi) is n_phi / 2 (n_phi for m = 0): the budget costs a few Bessel values per
ring. The RMS over the disk is sqrt(E ||delta||^2 / (pi a^2)), the inversion's RMS definition.

- With the gain estimated, delta_c (:mod:`solver.gainmode`) is removed from the map, and with it
  the noise's share along it: E ||(1 - P_c) delta||^2 = E ||delta||^2 - var(<FA / G, psi>) with
  psi = Laplacian^-1 of the unit-norm mode (a radial ODE here).
- Terms removed after the solve (``invert --remove``: piston, tilt, focus, by least squares
  over the disk, after delta_c) take their span's share: with u_i an orthonormal basis of it,
  E ||(1 - P_t) y||^2 = E ||y||^2 - sum_i var(<u_i, y>), y the map after delta_c's removal,
  and <u_i, y> = <w_i, delta> with w_i = u_i - c <c, u_i> (c the unit delta_c; w_i = u_i with
  the gain known), so var(<FA / G, Laplacian^-1 w_i>) as for delta_c (tilt: m = 1, where
  Laplacian^-1 r = (r^3 - a^2 r) / 8). The same holds for the references' part, and for the
  rim targets' harmonic error, whose constant is partly removed by delta_c and by piston or
  focus (a refocus removes 3/4 of its mean square) and whose m = 1 term is a tilt.
- Rim targets of std sigma_t fix the harmonic part; a least-squares Fourier fit of order M to N
  targets spread round the rim leaves mean-square sigma_t^2 / N (1 + sum_m 2 / (m + 1)) over the
  disk (the harmonics (r/a)^m have mean square 1 / (m + 1) there). Without targets the harmonic
  part is not bounded by the data at all: the map assumes zero on the rim.

- Drift references: when the readings are corrected for receiver drift by reference readings
  every K lines (each the mean of S readings), a reference's own error e_k (relative std
  sigma_1 / sqrt(S), sigma_1 one reading's) is applied to every cell read near it: line j gets
  epsilon_j = sum_k H_jk e_k - e_0, H the linear interpolation in time between the references
  that bracket the line (at its middle) and e_0 the first reference's, relative to which the
  gains are taken. That error is constant along theta, so a mode's row weights add before they
  are squared, and its azimuthal weight is ||H^T cos(m phi)||^2 + ||H^T sin(m phi)||^2 instead of
  n_phi / 2. With the gain estimated its phi-constant part (m = 0) is a scale error and goes
  with the gain; a ``smooth`` correction (line fits over several references) averages the
  references and is counted here as ``linear``, an upper bound.
- Cells that carry no data (``used`` false: the cells obstacles hide, which the inversion
  fills from the rest of their row): a row with n_used of its n_phi cells measured has its
  variance scaled by n_phi / n_used, the variance of a mean over the cells that remain (the
  fill along phi spreads their noise over the row); a row with none (a feed cabin's) adds
  nothing, to the readings' part or to the references': the map is not reported there
  (solver.central). An approximation: against the scatter of linear inversions of scans
  with a quadripod's strips it predicts 7 % low, with a cabin as well 3 % high (tests/solver).

Checked against the scatter of the inversion itself over noisy scans in tests/solver.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import cumulative_trapezoid, trapezoid
from scipy.ndimage import map_coordinates
from scipy.special import jn_zeros, jv

from raysim.maps.sphere import SphereGrid
from solver.boundary import MAX_HARMONICS
from solver.equation import G
from solver.errors import SolverError
from solver.fit import parse_terms
from solver.resample import PAD, extend_rows, usable_rows

J_MAX = 80.0  # highest Bessel zero kept: the variance beyond falls as (j_01 / J_MAX)^2 ~ 1e-3
DB = math.log(10.0) / 10.0  # relative intensity per dB
DELTA_C = ("linear", "refocus")


def relative_std(noise_db: float, readings: int) -> float:
    """Relative std of a cell's averaged reading: (ln 10 / 10) s_dB / sqrt(K)."""
    return DB * noise_db / math.sqrt(readings)


@dataclass(frozen=True)
class Mode:
    """One Dirichlet mode's share of the noise: order m, radial index n, RMS (m, both
    azimuthal phases together)."""

    m: int
    n: int
    rms: float

    @property
    def label(self) -> str:
        return f"J{self.m}(j{self.m},{self.n} r/a)" + (f" cos/sin {self.m} phi" if self.m else "")


@dataclass(frozen=True)
class Budget:
    """The predicted deformation RMS (m) of one plan and noise level (see the module).

    ``noise``: the noise's part after delta_c's removal (when the gain is estimated);
    ``delta_c``: the share along delta_c (removed with an estimated gain, else kept);
    ``harmonic``: the rim targets' part (None without targets: unbounded); ``modes``: the
    largest Dirichlet-mode shares, largest first; ``sigma``: relative std per cell;
    ``reference``: the drift references' part (0 when the readings are not drift-corrected);
    ``removed``: the terms removed after the solve, whose share every part has lost.
    """

    noise: float
    delta_c: float
    delta_c_removed: bool
    harmonic: float | None
    modes: tuple[Mode, ...]
    sigma: float
    reference: float = 0.0
    removed: tuple[str, ...] = ()   # the terms removed after the solve (invert --remove)

    @property
    def total(self) -> float:
        """The RMS the map is predicted to have (noise, references and rim targets, m)."""
        return math.hypot(self.noise, self.reference, self.harmonic or 0.0)


QUADRATURE = 6  # radius samples per sphere row in the rings' radial integrals


@dataclass(frozen=True)
class Rings:
    """The scan's usable sphere rows seen from the aperture, as the inversion resamples them.

    ``r`` (m): radius samples 0..a; ``G`` (m) there; ``n_phi`` cells of ``dphi`` (rad) per ring;
    ``basis[p]`` (rows, samples): the value at each radius of the aperture field the resampling
    makes from a unit value in one row (:func:`solver.resample.sphere_to_aperture`: the cubic
    continuation to the rim, the padding across the pole, the cubic spline), for p = 0 (even
    azimuthal order m: the rows across the pole enter with +1) and p = 1 (odd m: -1).
    """

    r: NDArray[np.float64]
    basis: tuple[NDArray[np.float64], NDArray[np.float64]]
    G: NDArray[np.float64]
    n_phi: int
    dphi: float


def rings(sphere: SphereGrid, F: float, D: float) -> Rings:
    """The usable rows of ``sphere`` (:func:`solver.resample.usable_rows`) as aperture rings."""
    if not sphere.full_circle:
        raise SolverError("the budget needs a scan over the full circle in phi (0..360 deg)")
    n = usable_rows(sphere, F, D)
    a = 0.5 * D
    r = np.linspace(0.0, a, QUADRATURE * n + 1)
    it = (2.0 * np.arctan(r / (2.0 * F)) - sphere.theta[0]) / sphere.dtheta + PAD
    across_pole = sphere.theta_min <= 1e-12 and sphere.n_phi % 2 == 0
    basis = []
    for sign in (1.0, -1.0):
        columns = []
        for q in range(n):
            unit = np.zeros((n, 1))
            unit[q] = 1.0
            table = extend_rows(unit, n)[:, 0]
            before = sign * table[:PAD][::-1] if across_pole else np.repeat(table[:1], PAD)
            padded = np.concatenate([before, table, np.repeat(table[-1:], PAD)])
            columns.append(map_coordinates(padded, [it], order=3, mode="nearest", prefilter=True))
        basis.append(np.array(columns))
    return Rings(r, (basis[0], basis[1]), G(r, F, sphere.radius), sphere.n_phi, sphere.dphi)


def spline_response(m: int, dphi: float) -> float:
    """Integral of the cubic interpolating spline of cos(m phi_j) against cos(m phi), over
    the same sum: sinc^4(m dphi / 2) / ((2 + cos(m dphi)) / 3)."""
    w = m * dphi
    return float(np.sinc(w / (2.0 * math.pi)) ** 4 / ((2.0 + math.cos(w)) / 3.0))


def _radial_inverse(s: NDArray[np.float64], f: NDArray[np.float64]) -> NDArray[np.float64]:
    """u on the radius samples ``s`` (0..a) with Laplacian u = f (radial), u(a) = 0."""
    inner = cumulative_trapezoid(s * f, s, initial=0.0)
    slope = np.divide(inner, s, out=np.zeros_like(s), where=s > 0)
    u = cumulative_trapezoid(slope, s, initial=0.0)
    return u - u[-1]


def delta_c_shape(s: NDArray[np.float64], F: float, R: float, kind: str) -> NDArray[np.float64]:
    """delta_c on the radius samples ``s`` (0..a): the linear answer's (G Laplacian = 1) or a
    model-based answer's refocus (a^2 - r^2) / kappa (:mod:`solver.gainmode`)."""
    if kind == "linear":
        return _radial_inverse(s, 1.0 / G(s, F, R))
    if kind == "refocus":
        a = s[-1]
        return (a * a - s * s) / (2.0 * (4.0 * F * F + a * a) / R - 8.0 * F)
    raise SolverError(f"unknown delta_c shape {kind!r}: choose {' or '.join(DELTA_C)}")


def harmonic_rms(n_targets: int, target_std: float, constant_kept: float = 1.0,
                 tilt_removed: bool = False) -> float:
    """RMS (m) over the disk of the harmonic fit's error from N targets of std ``target_std``:
    of its constant, the share ``constant_kept`` of the mean square that the map's removals
    leave (see :class:`Removal`), and of its m = 1 term none when tilt is removed."""
    order = min(MAX_HARMONICS, (n_targets - 1) // 2)
    mean_square = constant_kept + sum(2.0 / (m + 1.0) for m in range(1, order + 1)
                                      if not (m == 1 and tilt_removed))
    return target_std * math.sqrt(mean_square / n_targets)


@dataclass(frozen=True)
class Removal:
    """What the map's removals take from the budget, per unit variance (m^2 over the disk):
    delta_c's (with the gain estimated, already in ``along_delta_c``) and then the removed
    ``terms`` (see the module).

    ``readings``, ``references``: the mean squares the terms remove from the readings' and the
    references' parts; ``constant_kept``: the share of a constant's mean square left (the rim
    targets' piston error); ``modes``, ``reference_modes``: (m, n, mean square) per Dirichlet
    mode after the removals."""

    terms: tuple[str, ...]
    readings: float
    references: float
    constant_kept: float
    modes: tuple[tuple[int, int, float], ...]
    reference_modes: tuple[tuple[int, int, float], ...]

    @property
    def tilt(self) -> bool:
        """Whether tilt is removed (and with it the rim targets' m = 1 error)."""
        return "tilt" in self.terms


@dataclass(frozen=True)
class NoiseResponse:
    """The map's mean-square response (m^2 over the disk, per unit relative variance of a
    cell's reading) of one scan geometry: per Dirichlet mode, and along delta_c; and per unit
    relative variance of a drift reference (``reference``: per mode, empty when the readings
    are not drift-corrected)."""

    modes: tuple[tuple[int, int, float], ...]   # (m, n, mean square)
    total: float
    along_delta_c: float
    reference: tuple[tuple[int, int, float], ...] = ()
    unused_cells: int = 0   # usable cells that carry no data (blocked), counted as such
    #: what the removals take, with the gain known and with it estimated (delta_c removed
    #: first); None: nothing but delta_c, whose per-mode shares are then not projected
    removals: tuple[Removal, Removal] | None = None

    def reference_share(self, gain_known: bool) -> float:
        """Mean square (m^2) per unit reference variance; m = 0 goes with an estimated gain."""
        return sum(ms for m, _, ms in self.reference if gain_known or m > 0)

    def removal(self, gain_known: bool) -> Removal:
        """The :class:`Removal` of the gain's case (nothing removed when none was computed)."""
        if self.removals is not None:
            return self.removals[0 if gain_known else 1]
        return Removal((), 0.0, 0.0, 1.0, self.modes, self.reference)

    def budget(self, noise_db: float, readings: int = 1, gain_known: bool = False,
               rim_targets: int = 0, target_std: float = 0.0, n_modes: int = 6,
               reference_samples: int = 0) -> Budget:
        """The :class:`Budget` of readings of ``noise_db`` averaged ``readings`` times, drift
        references (when the response has them) each the mean of ``reference_samples``."""
        sigma = relative_std(noise_db, readings)
        v = sigma**2
        removal = self.removal(gain_known)
        noise = self.total if gain_known else self.total - self.along_delta_c
        noise = max(noise - removal.readings, 0.0)
        harmonic = (harmonic_rms(rim_targets, target_std, removal.constant_kept, removal.tilt)
                    if rim_targets else None)
        reference, v_ref = 0.0, 0.0
        if self.reference and reference_samples > 0:
            v_ref = relative_std(noise_db, reference_samples) ** 2
            left = max(self.reference_share(gain_known) - removal.references, 0.0)
            reference = math.sqrt(v_ref * left)
        # each mode's share of the readings' and of the references' parts (m = 0 references go
        # with an estimated gain, as in reference_share)
        own = {(m, n): v * ms for m, n, ms in removal.modes}
        for m, n, ms in removal.reference_modes:
            if (m, n) in own and (gain_known or m > 0):
                own[(m, n)] += v_ref * ms
        largest = sorted(own.items(), key=lambda item: -item[1])[:n_modes]
        return Budget(math.sqrt(v * noise), math.sqrt(v * self.along_delta_c), not gain_known,
                      harmonic, tuple(Mode(m, n, math.sqrt(ms)) for (m, n), ms in largest),
                      sigma, reference, removal.terms)

    def readings_for(self, target: float, noise_db: float, **options) -> int | None:
        """Readings per point for a predicted total RMS of at most ``target`` (m); None when
        the rim targets' and the references' parts alone exceed it (more readings per point
        do not shrink those)."""
        one = self.budget(noise_db, 1, **options)
        left = target**2 - (one.harmonic or 0.0) ** 2 - one.reference**2
        if left <= 0:
            return None
        return max(1, math.ceil((one.noise**2 / left) * (1 - 1e-12)))


def reference_weights(n_phi: int, every: int) -> NDArray[np.float64]:
    """H (n_phi, references) minus the first reference: each phi line's drift-gain error per
    unit error of each reference (see the module). References are read before the first line,
    after every ``every`` lines and after the last; a line is read between two of them, and
    the gain at its middle is interpolated linearly between them."""
    bounds = np.unique(np.append(np.arange(0, n_phi, every), n_phi)).astype(np.float64)
    H = np.zeros((n_phi, bounds.size))
    for j in range(n_phi):
        k = min(int(np.searchsorted(bounds, j + 0.5)) - 1, bounds.size - 2)
        t = (j + 0.5 - bounds[k]) / (bounds[k + 1] - bounds[k])
        H[j, k] += 1.0 - t
        H[j, k + 1] += t
    H[:, 0] -= 1.0
    return H


def _radial_kernel(ring: Rings) -> NDArray[np.float64]:
    """dA / (dphi G) along the radius samples (trapezoid weights), m / m."""
    quad = np.full(ring.r.size, ring.r[1] - ring.r[0])
    quad[[0, -1]] *= 0.5
    return quad * ring.r / ring.G


def _mode_rows(ring: Rings, a: float, kernel: NDArray[np.float64]):
    """Per azimuthal order m: the Bessel zeros j_mn < J_MAX, the unit-norm factor of each mode,
    and each mode's weight on each sphere row (<FA / G, phi_k> per unit value in the row)."""
    m = 0
    while True:
        zeros = jn_zeros(m, max(1, int(J_MAX / math.pi) + 2))
        zeros = zeros[zeros < J_MAX]
        if zeros.size == 0:
            return
        # unit-norm radial factor: int_0^a J_m(j r/a)^2 r dr = a^2 J_{m+1}(j)^2 / 2
        norm2 = 1.0 / (0.5 * a * a * jv(m + 1, zeros) ** 2 * (2.0 * math.pi if m == 0 else math.pi))
        rows = (jv(m, np.outer(zeros, ring.r / a)) * kernel) @ ring.basis[m % 2].T
        yield m, zeros, norm2, rows
        m += 1


def row_factors(used: NDArray[np.bool_] | None, n_rows: int) -> tuple[NDArray[np.float64], int]:
    """Per usable row, the factor on its noise variance when only the ``used`` cells
    (n_theta, n_phi) carry data: n_phi / n_used, 0 for a row with none (see the module); and
    the usable cells without data."""
    if used is None:
        return np.ones(n_rows), 0
    rows = np.asarray(used, dtype=bool)[:n_rows]
    n_used = rows.sum(axis=1)
    factors = np.divide(rows.shape[1], n_used, out=np.zeros(n_rows), where=n_used > 0)
    return factors, int(rows.size - n_used.sum())


def noise_response(sphere: SphereGrid, F: float, D: float, delta_c: str = "refocus",
                   reference_every: int | None = None,
                   used: NDArray[np.bool_] | None = None,
                   remove: Sequence[str] = ()) -> NoiseResponse:
    """The :class:`NoiseResponse` of a scan on ``sphere`` of a dish (F, D in m), with drift
    references every ``reference_every`` phi lines (None: not drift-corrected); see the module.

    ``used`` (n_theta, n_phi) bool: the cells that carry data (None: all of them); a scan with
    obstacles passes the cells they leave (not ``blocked``). ``remove``: the terms the map has
    removed after the solve (piston, tilt, focus: ``invert --remove``)."""
    terms = parse_terms(remove)
    ring = rings(sphere, F, D)
    if used is not None and np.shape(used) != (sphere.n_theta, sphere.n_phi):
        raise SolverError(f"the used-cell mask {np.shape(used)} is not the scan's grid "
                          f"({sphere.n_theta}, {sphere.n_phi})")
    factors, unused = row_factors(used, ring.basis[0].shape[0])
    a = 0.5 * D
    area = math.pi * a * a
    H = None if reference_every is None else reference_weights(ring.n_phi, reference_every)
    phi = np.arange(ring.n_phi) * ring.dphi
    shares: list[tuple[int, int, float]] = []
    references: list[tuple[int, int, float]] = []
    kernel = _radial_kernel(ring)
    orders: dict[int, _Order] = {}  # m = 0 and 1, which the removals reach
    for m, zeros, norm2, rows in _mode_rows(ring, a, kernel):
        # <FA / G, phi_k> = sum over cells of noise x (row weight) x (azimuthal weight)
        spline = (ring.dphi * spline_response(m, ring.dphi)) ** 2
        cells = ring.n_phi if m == 0 else ring.n_phi / 2.0           # sum of cos^2 over a ring
        phases = 1 if m == 0 else 2
        scale = norm2 / (zeros / a) ** 4 / area
        var = phases * spline * cells * scale * np.sum(rows**2 * factors, axis=1)
        shares += [(m, n + 1, float(v)) for n, v in enumerate(var)]
        lines = (0.0, 0.0)
        if H is not None:
            # one error per line, the same in every row: the rows' weights add first
            lines = (float(np.sum((H.T @ np.cos(m * phi)) ** 2)),
                     float(np.sum((H.T @ np.sin(m * phi)) ** 2)) if m else 0.0)
            ref = spline * sum(lines) * scale * np.sum(rows * (factors > 0), axis=1) ** 2
            references += [(m, n + 1, float(v)) for n, v in enumerate(ref)]
        if m <= 1:  # the same sums between two modes: their coefficients' covariance
            root = np.sqrt(scale)
            orders[m] = _Order(spline * cells * np.outer(root, root) * ((rows * factors) @ rows.T),
                               root * np.sum(rows * (factors > 0), axis=1), spline * sum(lines),
                               lines, np.sqrt(norm2), zeros)
    s = np.linspace(0.0, a, 4001)
    shape = delta_c_shape(s, F, sphere.radius, delta_c)
    unit = shape / math.sqrt(_disk_dot(s, shape, shape))
    sums = _Sums(ring, kernel, factors, s, area)
    along = sums.readings(_radial_inverse(s, unit), 0)
    removals = tuple(_removal(terms, sums, orders, shares, references, unit if estimated else None)
                     for estimated in (False, True))
    return NoiseResponse(tuple(shares), sum(v for *_, v in shares), along, tuple(references),
                         unused, removals)


@dataclass(frozen=True)
class _Order:
    """One azimuthal order's Dirichlet modes: the coefficients' covariance (one phase, m^2 per
    unit variance), the references' coefficient per unit error of a line's gain and their
    spline times lines factor (both phases) and lines per phase (cos, sin), each mode's
    unit-norm factor and Bessel zero."""

    cov: NDArray[np.float64]
    reference: NDArray[np.float64]
    reference_factor: float
    lines: tuple[float, float]
    norm: NDArray[np.float64]
    zeros: NDArray[np.float64]

    def coefficients(self, s: NDArray[np.float64], f: NDArray[np.float64], m: int
                     ) -> NDArray[np.float64]:
        """<f(r) cos(m phi), phi_mn> for each mode n (f on the radius samples ``s``)."""
        a = s[-1]
        modes = self.norm[:, None] * jv(m, np.outer(self.zeros, s / a))
        return trapezoid((2.0 * math.pi if m == 0 else math.pi) * s * f * modes, s, axis=1)


def _disk_dot(s: NDArray[np.float64], f: NDArray[np.float64], g: NDArray[np.float64]) -> float:
    """The inner product over the disk of two radial functions on the radius samples ``s``."""
    return float(trapezoid(2.0 * math.pi * s * f * g, s))


@dataclass(frozen=True)
class _Sums:
    """var(<delta, u>) for a shape u = w(r) cos(m phi), from psi = Laplacian^-1 w on the radius
    samples ``s``: the readings' (one phase) and a line error's, as mean squares over the disk."""

    ring: Rings
    kernel: NDArray[np.float64]
    factors: NDArray[np.float64]
    s: NDArray[np.float64]
    area: float

    def _weights(self, psi: NDArray[np.float64], m: int) -> NDArray[np.float64]:
        """Each sphere row's weight in <FA / G, psi cos(m phi)> per unit value in the row."""
        return (np.interp(self.ring.r, self.s, psi) * self.kernel) @ self.ring.basis[m % 2].T

    def _spline(self, m: int) -> float:
        return (self.ring.dphi * spline_response(m, self.ring.dphi)) ** 2

    def readings(self, psi: NDArray[np.float64], m: int) -> float:
        cells = self.ring.n_phi if m == 0 else self.ring.n_phi / 2.0
        return (self._spline(m) * cells * float(np.sum(self._weights(psi, m) ** 2 * self.factors))
                / self.area)

    def references(self, psi: NDArray[np.float64], m: int, lines: float) -> float:
        weight = float(np.sum(self._weights(psi, m) * (self.factors > 0)))
        return self._spline(m) * lines * weight**2 / self.area


def _term_shapes(s: NDArray[np.float64], terms: Sequence[str]) -> list[NDArray[np.float64]]:
    """An orthonormal basis (over the disk) of the removed axisymmetric terms: piston, focus."""
    basis: list[NDArray[np.float64]] = []
    for name, f in (("piston", np.ones_like(s)), ("focus", s * s)):
        if name in terms:
            for u in basis:
                f = f - _disk_dot(s, f, u) * u
            basis.append(f / math.sqrt(_disk_dot(s, f, f)))
    return basis


def _removal(terms: tuple[str, ...], sums: _Sums, orders: dict[int, _Order],
             shares: list[tuple[int, int, float]], references: list[tuple[int, int, float]],
             unit: NDArray[np.float64] | None) -> Removal:
    """The :class:`Removal` of ``terms`` after delta_c's (``unit`` on the radius samples; None
    with the gain known): see the module. The per-mode shares come from the m = 0 and m = 1
    coefficients' covariances projected off the removed shapes (their mode coefficients: the
    modes' truncation at J_MAX leaves a shape's tail, which the totals, taken from the shapes
    themselves, do not need)."""
    s = sums.s
    a = s[-1]
    shapes = _term_shapes(s, terms)
    readings = references_removed = 0.0
    after_c = (lambda f: f) if unit is None else (lambda f: f - _disk_dot(s, f, unit) * unit)
    for u in shapes:
        psi = _radial_inverse(s, after_c(u))
        readings += sums.readings(psi, 0)
        if unit is None:  # m = 0 reference errors go with an estimated gain
            references_removed += sums.references(psi, 0, orders[0].lines[0])
    tilt_norm = math.sqrt(0.25 * math.pi * a**4)       # of r cos(phi) over the disk
    if "tilt" in terms:
        psi = (s**3 - a * a * s) / 8.0 / tilt_norm
        readings += 2.0 * sums.readings(psi, 1)
        references_removed += sum(sums.references(psi, 1, lines) for lines in orders[1].lines)
    constant = after_c(np.ones_like(s))
    for u in shapes:
        constant = constant - _disk_dot(s, constant, u) * u
    kept = _disk_dot(s, constant, constant) / _disk_dot(s, np.ones_like(s), np.ones_like(s))
    # per mode: the coefficients x become M x (M: the projections, delta_c's first); each
    # order's shares after them, both phases for m > 0, and its references' shares
    after: dict[int, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
    for m, order in orders.items():
        M = np.eye(order.zeros.size)
        if m == 0 and unit is not None:
            c = order.coefficients(s, unit, 0)
            M = M - np.outer(c, c)
        for u in shapes if m == 0 else [s / tilt_norm] if "tilt" in terms else []:
            t = order.coefficients(s, u, m)
            M = (np.eye(t.size) - np.outer(t, t)) @ M
        after[m] = ((1 if m == 0 else 2) * np.einsum("ij,jk,ik->i", M, order.cov, M),
                    order.reference_factor * (M @ order.reference) ** 2)
    modes = [(m, n, float(after[m][0][n - 1]) if m in after else ms) for m, n, ms in shares]
    reference_modes = [(m, n, float(after[m][1][n - 1]) if m in after else ms)
                       for m, n, ms in references]
    return Removal(terms, readings, references_removed, kept, tuple(modes),
                   tuple(reference_modes))


def noise_budget(sphere: SphereGrid, F: float, D: float, noise_db: float, readings: int = 1,
                 gain_known: bool = False, rim_targets: int = 0, target_std: float = 0.0,
                 delta_c: str = "refocus", n_modes: int = 6, reference_every: int | None = None,
                 reference_samples: int = 0, used: NDArray[np.bool_] | None = None,
                 remove: Sequence[str] = ()) -> Budget:
    """The budget of a scan on ``sphere`` of a dish (F, D in m), drift references every
    ``reference_every`` lines of ``reference_samples`` readings (None: no drift correction),
    the terms ``remove`` (piston, tilt, focus) removed from the map after the solve; see the
    module docstring."""
    response = noise_response(sphere, F, D, delta_c, reference_every, used, remove)
    return response.budget(noise_db, readings, gain_known, rim_targets, target_std, n_modes,
                           reference_samples)

