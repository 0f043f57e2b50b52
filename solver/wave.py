"""How wave-optics intensity responds to a surface deformation: weights and a preconditioner.

Frame and units (docs/physics.md): sphere cells (theta, phi in rad) around the focus (0, 0, F), the
aperture grid (x, y in m), delta in m, FA dimensionless, wavelength and distances in m, spatial
frequencies kappa in cycles per metre. Time convention exp(+j w t), E_inc = e exp(+j k z).

The deformation-intensity equation FA = G Laplacian(delta) is the GO limit. Physical optics
adds two effects, both checked against finite differences of the PO engine on the paper's
dish at 0.3 GHz (about 10 % agreement, row by row):

1. The edge wave. The field on the sphere is the geometric wave E_geo (amplitude rho / R,
   uniform phase -k (F - R)) plus the rim's diffracted wave. A deformation delta at a ray's
   reflection point changes the geometric wave's amplitude (GO's curvature response) and its
   phase by k (1 + cos theta) delta, while the edge wave of the fixed rim stays. To first order

       FA ~ p G Laplacian(delta) - q delta,
       p = Re(conj(E0) . E_geo) / I0,   q = -2 k (1 + cos theta) Im(conj(E0) . E_geo) / I0,

   with E0 the ideal reflector's full field (:func:`interference`). Without an edge wave p = 1,
   q = 0. The q term is holographic (the edge wave is the reference wave): it answers to delta
   itself, not its Laplacian, and at 0.3 GHz it outweighs GO's response for shapes wider than
   about 30 m (the focus-like ones above all: 60 times GO's near the axis, of either sign).
2. Fresnel smoothing. A ripple of spatial frequency kappa answers as sinc(lambda z_eff kappa^2)
   times GO's, z_eff = (rho - R) rho / R (:func:`effective_distance`: the converging wave's
   path, rescaled by the Fresnel scaling theorem; the aperture-to-wavefront map is locally an
   isometry). At 0.3 GHz on the paper's dish a 21 m ripple keeps 0.5 to 0.84 of its GO
   signal; ripples under 9 m (axis) to 16 m (rim) answer with the opposite sign or not at all.

:func:`amplitude_weight` sqrt(I0 / I_GO) turns an FA misfit into 2 d|E| / |E_GO|, whose GO part
stays within a factor 1 / sqrt(1 + eps^2) of GO's (eps = |edge| / |geometric| wave) where FA's
own response blows up in the dark rings of the diffraction pattern: it weights the linear
solve and every misfit. :class:`WaveCorrection` inverts the model above approximately, two
levels: the focus-like shape B (Laplacian B = 1 / G, zero rim: the answer to a constant FA)
and the unknown scale are fitted by least squares with the full p, q response; the rest goes
through the GO Poisson solve after a Fresnel filter (:class:`FresnelFilter`) that divides by
the sinc where it is large and drops the bands beyond its first zero.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from raysim.constants import C0, wavenumber
from raysim.maps.sphere import SphereGrid, aperture_radius, ideal_go_cell_mean, ideal_go_intensity
from solver.aperture import ApertureGrid
from solver.linear import LinearInverse

P_MIN = 0.2         # p is kept within [P_MIN, 1 / P_MIN] where it divides


def effective_distance(r: NDArray[np.float64], F: float, R: float) -> NDArray[np.float64]:
    """z_eff = (rho - R) rho / R (m), rho = F + r^2 / 4F: the reflected wave's plane-wave path."""
    rho = F + np.asarray(r, dtype=np.float64) ** 2 / (4.0 * F)
    return (rho - R) * rho / R


def transfer(kappa2: NDArray[np.float64], wavelength: float, z_eff: float) -> NDArray[np.float64]:
    """H = sin(x) / x, x = pi lambda z_eff kappa^2: wave over GO intensity response."""
    return np.sinc(wavelength * z_eff * kappa2)  # numpy's sinc(u) = sin(pi u) / (pi u)


@dataclass(frozen=True)
class FresnelFilter:
    """FA on the aperture -> FA / H on the bands where H >= h_min (first lobe), zero beyond.

    z_eff varies across the aperture: the filter is applied for ``n_bands`` values of z_eff
    spanning it and the results are blended at each point by its own z_eff.
    """

    grid: ApertureGrid
    F: float
    R: float
    wavelength: float
    h_min: float = 0.3
    n_bands: int = 6

    @cached_property
    def _z_eff(self) -> NDArray[np.float64]:
        return effective_distance(self.grid.r, self.F, self.R)

    @cached_property
    def _bands(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The z_eff of each band and its filter on the rfft2 grid of the 2N-padded plane."""
        z = self._z_eff[self.grid.mask]
        zs = np.geomspace(z.min(), z.max(), self.n_bands)
        n = 2 * self.grid.N
        ky = np.fft.fftfreq(n, self.grid.h)
        kx = np.fft.rfftfreq(n, self.grid.h)
        kappa2 = kx[None, :] ** 2 + ky[:, None] ** 2
        filters = []
        for z_eff in zs:
            H = transfer(kappa2, self.wavelength, z_eff)
            keep = (self.wavelength * z_eff * kappa2 < 1.0) & (H >= self.h_min)
            filters.append(np.where(keep, 1.0 / np.maximum(H, self.h_min), 0.0))
        return zs, np.stack(filters)

    def shortest_period(self) -> tuple[float, float]:
        """Shortest period (m) passed on the axis and at the rim (the largest z_eff)."""
        zs, _ = self._bands
        lo, hi = 0.0, 1.0  # sinc(u) = h_min by bisection on the first lobe
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if np.sinc(mid) > self.h_min else (lo, mid)
        return (float(np.sqrt(self.wavelength * zs[0] / lo)),
                float(np.sqrt(self.wavelength * zs[-1] / lo)))

    def __call__(self, fa: NDArray[np.float64]) -> NDArray[np.float64]:
        """Filtered ``fa`` (N, N; NaN outside the aperture); zero-padded to 2N for the FFT."""
        grid, N = self.grid, self.grid.N
        padded = np.zeros((2 * N, 2 * N))
        padded[:N, :N] = np.where(grid.mask & np.isfinite(fa), fa, 0.0)
        spectrum = np.fft.rfft2(padded)
        zs, filters = self._bands
        bands = np.stack([np.fft.irfft2(spectrum * w, s=padded.shape)[:N, :N] for w in filters])
        where = np.interp(self._z_eff, zs, np.arange(len(zs)))
        lo = np.clip(np.floor(where).astype(np.int64), 0, len(zs) - 2)
        t = where - lo
        jj, ii = np.indices((N, N))
        return grid.masked((1.0 - t) * bands[lo, jj, ii] + t * bands[lo + 1, jj, ii])


def go_ideal(sphere: SphereGrid, F: float, sampling: str = "centre") -> NDArray[np.float64]:
    """The ideal GO intensity (n_theta, 1): cell means for ``cell_mean`` data, else centres."""
    if sampling == "cell_mean":
        e = sphere.theta_edges
        return ideal_go_cell_mean(e[:-1], e[1:], F, sphere.radius)[:, None]
    return ideal_go_intensity(sphere.theta, F, sphere.radius)[:, None]


def amplitude_weight(intensity_ideal: NDArray[np.float64], sphere: SphereGrid, F: float,
                     sampling: str = "centre") -> NDArray[np.float64]:
    """sqrt(I0 / I_GO) per sphere cell (dimensionless; NaN where I0 is missing).

    1 to rounding for GO data; for wave data it follows the diffraction rings of the ideal
    reflector's intensity (0.5 to 1.7 on the paper's case at 0.3 GHz).
    """
    ideal = np.asarray(intensity_ideal, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.clip(ideal, 0.0, None) / go_ideal(sphere, F, sampling))


def geometric_field(sphere: SphereGrid, F: float, k: float,
                    polarization: float = 0.0) -> NDArray[np.complex128]:
    """The GO reflected field E_geo (n_theta, n_phi, 3) at the cell centres (V/m per V/m).

    Amplitude rho / R; direction the incident E mirrored in the normal at the reflection
    point (E_r = -E_i + 2 (n . E_i) n); phase: k z_s at the surface point (E_inc ~ exp(+j k z)),
    less k (rho - R) on the way to the sphere, rho = F + z_s: -k (F - R) for every ray.
    """
    theta, phi = np.meshgrid(sphere.theta, sphere.phi, indexing="ij")
    r = aperture_radius(theta, F)
    x, y = r * np.cos(phi), r * np.sin(phi)
    n = np.stack([-x / (2.0 * F), -y / (2.0 * F), np.ones_like(x)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    e_i = np.array([np.cos(polarization), np.sin(polarization), 0.0])
    e_r = -e_i + 2.0 * (n @ e_i)[..., None] * n
    amplitude = np.sqrt(ideal_go_intensity(theta, F, sphere.radius))
    return (amplitude * np.exp(-1j * k * (F - sphere.radius)))[..., None] * e_r


def interference(E0: NDArray[np.complex128], sphere: SphereGrid, F: float, k: float,
                 polarization: float = 0.0) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(p, q) per sphere cell of FA ~ p G Laplacian(delta) - q delta (q in 1/m): module docs."""
    geo = geometric_field(sphere, F, k, polarization)
    cross = np.sum(np.conj(E0) * geo, axis=-1)
    I0 = np.sum(np.abs(E0) ** 2, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        p = np.real(cross) / I0
        q = -2.0 * k * (1.0 + np.cos(sphere.theta))[:, None] * np.imag(cross) / I0
    return p, q


class WaveCorrection:
    """The wave refinement's preconditioner: weighted FA misfit on the sphere -> surface update.

    ``inverse`` (:class:`solver.linear.LinearInverse`) supplies the GO pieces:
    ``to_aperture(values_on_sphere)``, ``poisson(fa_on_aperture)`` (zero rim) and
    ``rim_update(delta)``. ``E0`` is the ideal reflector's complex field (n_theta, n_phi, 3),
    ``weight`` the amplitude weight the misfits carry. Calling it with (misfit, delta) returns
    the update (m, (N, N)) and, with ``fit_gain``, the relative step of the scan's scale.
    ``fresnel`` False leaves out the Fresnel filter, for a model that answers to fine shapes
    as GO does (go+edge: the geometric wave plus edge waves has no Fresnel smoothing).
    """

    def __init__(self, inverse: LinearInverse, E0: NDArray[np.complex128], frequency_hz: float,
                 polarization: float, weight: NDArray[np.float64], fit_gain: bool,
                 fresnel: bool = True) -> None:
        scan, grid = inverse.scan, inverse.grid
        k = wavenumber(frequency_hz)
        p, q = interference(E0, scan.sphere, scan.F, k, polarization)
        mask = grid.mask
        self.inverse, self.fit_gain = inverse, fit_gain
        self.p = np.clip(np.nan_to_num(inverse.to_aperture(weight * p)[mask], nan=1.0),
                         P_MIN, 1.0 / P_MIN)
        q_in = np.nan_to_num(inverse.to_aperture(weight * q)[mask], nan=0.0)
        self.B = inverse.poisson(np.ones((grid.N, grid.N)))[mask]  # G Laplacian(B) = 1
        # the weighted misfit's answer to + B on the surface (p G Laplacian(B) - q B, p and q
        # weighted) and to a relative scale step (the weight itself), with the sign they enter
        columns = [self.p - q_in * self.B]
        if fit_gain:
            columns.append(-np.nan_to_num(inverse.to_aperture(weight)[mask], nan=1.0))
        self.columns = np.stack(columns, axis=1)
        self.filter = FresnelFilter(grid, scan.F, scan.R, C0 / frequency_hz) if fresnel else None

    def __call__(self, misfit: NDArray[np.float64], delta: NDArray[np.float64]):
        inverse, grid = self.inverse, self.inverse.grid
        mask = grid.mask
        m = inverse.to_aperture(misfit)
        coef, *_ = np.linalg.lstsq(self.columns, np.nan_to_num(m[mask]), rcond=None)
        rest = np.full((grid.N, grid.N), np.nan)
        rest[mask] = (np.nan_to_num(m[mask]) - self.columns @ coef) / self.p
        fine = inverse.poisson(self.filter(rest) if self.filter is not None else rest)[mask]
        fine -= (fine @ self.B) / (self.B @ self.B) * self.B  # B is the coarse level's
        update = np.full((grid.N, grid.N), np.nan)
        update[mask] = fine + coef[0] * self.B
        update += inverse.rim_update(delta + update)
        return (update, float(coef[1])) if self.fit_gain else update
