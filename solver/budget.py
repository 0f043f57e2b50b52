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
    ``reference``: the drift references' part (0 when the readings are not drift-corrected).
    """

    noise: float
    delta_c: float
    delta_c_removed: bool
    harmonic: float | None
    modes: tuple[Mode, ...]
    sigma: float
    reference: float = 0.0

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


def harmonic_rms(n_targets: int, target_std: float) -> float:
    """RMS (m) over the disk of the harmonic fit's error from N targets of std ``target_std``."""
    order = min(MAX_HARMONICS, (n_targets - 1) // 2)
    mean_square = 1.0 + sum(2.0 / (m + 1.0) for m in range(1, order + 1))
    return target_std * math.sqrt(mean_square / n_targets)


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
    #: ``modes`` once delta_c is removed (an estimated gain): the m = 0 shares of the map minus
    #: its projection on delta_c, from the m = 0 coefficients' covariance (see the module)
    modes_without_delta_c: tuple[tuple[int, int, float], ...] = ()

    def reference_share(self, gain_known: bool) -> float:
        """Mean square (m^2) per unit reference variance; m = 0 goes with an estimated gain."""
        return sum(ms for m, _, ms in self.reference if gain_known or m > 0)

    def budget(self, noise_db: float, readings: int = 1, gain_known: bool = False,
               rim_targets: int = 0, target_std: float = 0.0, n_modes: int = 6,
               reference_samples: int = 0) -> Budget:
        """The :class:`Budget` of readings of ``noise_db`` averaged ``readings`` times, drift
        references (when the response has them) each the mean of ``reference_samples``."""
        sigma = relative_std(noise_db, readings)
        v = sigma**2
        noise = self.total if gain_known else max(self.total - self.along_delta_c, 0.0)
        harmonic = harmonic_rms(rim_targets, target_std) if rim_targets else None
        reference, v_ref = 0.0, 0.0
        if self.reference and reference_samples > 0:
            v_ref = relative_std(noise_db, reference_samples) ** 2
            reference = math.sqrt(v_ref * self.reference_share(gain_known))
        shares = self.modes if gain_known else (self.modes_without_delta_c or self.modes)
        # each mode's share of the readings' and of the references' parts (m = 0 references go
        # with an estimated gain, as in reference_share)
        own = {(m, n): v * ms for m, n, ms in shares}
        for m, n, ms in self.reference:
            if (m, n) in own and (gain_known or m > 0):
                own[(m, n)] += v_ref * ms
        largest = sorted(own.items(), key=lambda item: -item[1])[:n_modes]
        return Budget(math.sqrt(v * noise), math.sqrt(v * self.along_delta_c), not gain_known,
                      harmonic, tuple(Mode(m, n, math.sqrt(ms)) for (m, n), ms in largest),
                      sigma, reference)

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
                   used: NDArray[np.bool_] | None = None) -> NoiseResponse:
    """The :class:`NoiseResponse` of a scan on ``sphere`` of a dish (F, D in m), with drift
    references every ``reference_every`` phi lines (None: not drift-corrected); see the module.

    ``used`` (n_theta, n_phi) bool: the cells that carry data (None: all of them); a scan with
    obstacles passes the cells they leave (not ``blocked``)."""
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
    axisymmetric = None  # the m = 0 modes' covariance and radial factors
    for m, zeros, norm2, rows in _mode_rows(ring, a, kernel):
        # <FA / G, phi_k> = sum over cells of noise x (row weight) x (azimuthal weight)
        spline = (ring.dphi * spline_response(m, ring.dphi)) ** 2
        cells = ring.n_phi if m == 0 else ring.n_phi / 2.0           # sum of cos^2 over a ring
        phases = 1 if m == 0 else 2
        scale = norm2 / (zeros / a) ** 4 / area
        var = phases * spline * cells * scale * np.sum(rows**2 * factors, axis=1)
        shares += [(m, n + 1, float(v)) for n, v in enumerate(var)]
        if m == 0:  # the same sums between two modes: their coefficients' covariance
            root = np.sqrt(scale)
            cov = spline * cells * np.outer(root, root) * ((rows * factors) @ rows.T)
            axisymmetric = (cov, zeros, norm2)
        if H is not None:
            # one error per line, the same in every row: the rows' weights add first
            lines = float(np.sum((H.T @ np.cos(m * phi)) ** 2)
                          + (np.sum((H.T @ np.sin(m * phi)) ** 2) if m else 0.0))
            ref = spline * lines * scale * np.sum(rows * (factors > 0), axis=1) ** 2
            references += [(m, n + 1, float(v)) for n, v in enumerate(ref)]
    s = np.linspace(0.0, a, 4001)
    shape = delta_c_shape(s, F, sphere.radius, delta_c)
    unit = shape / math.sqrt(float(trapezoid(2.0 * math.pi * s * shape**2, s)))
    psi = np.interp(ring.r, s, _radial_inverse(s, unit))
    along = float(ring.n_phi * ring.dphi**2
                  * np.sum(((psi * kernel) @ ring.basis[0].T) ** 2 * factors))
    return NoiseResponse(tuple(shares), sum(v for *_, v in shares), along / area,
                         tuple(references), unused,
                         _without_delta_c(shares, axisymmetric, s, unit, a))


def _without_delta_c(shares: list[tuple[int, int, float]], axisymmetric, s: NDArray[np.float64],
                     unit: NDArray[np.float64], a: float) -> tuple[tuple[int, int, float], ...]:
    """``shares`` with the m = 0 ones of the map less its projection on the unit delta_c shape
    ``unit`` (on the radius samples ``s``): with c the shape's coefficients on the m = 0 modes,
    the coefficients become (1 - c c^T) x, of covariance (1 - c c^T) C (1 - c c^T). Without
    it a mode close to delta_c (J0(j0,1 r/a) for a refocus) was listed at its share before the
    removal, above the whole budget's total."""
    if axisymmetric is None:
        return tuple(shares)
    cov, zeros, norm2 = axisymmetric
    modes = np.sqrt(norm2)[:, None] * jv(0, np.outer(zeros, s / a))
    c = trapezoid(2.0 * math.pi * s * unit * modes, s, axis=1)
    P = np.eye(len(c)) - np.outer(c, c)
    after = np.diag(P @ cov @ P)
    return tuple((m, n, float(after[n - 1]) if m == 0 else v) for m, n, v in shares)


def noise_budget(sphere: SphereGrid, F: float, D: float, noise_db: float, readings: int = 1,
                 gain_known: bool = False, rim_targets: int = 0, target_std: float = 0.0,
                 delta_c: str = "refocus", n_modes: int = 6, reference_every: int | None = None,
                 reference_samples: int = 0, used: NDArray[np.bool_] | None = None) -> Budget:
    """The budget of a scan on ``sphere`` of a dish (F, D in m), drift references every
    ``reference_every`` lines of ``reference_samples`` readings (None: no drift correction);
    see the module docstring."""
    response = noise_response(sphere, F, D, delta_c, reference_every, used)
    return response.budget(noise_db, readings, gain_known, rim_targets, target_std, n_modes,
                           reference_samples)
