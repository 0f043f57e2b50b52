"""The geometric wave's Fresnel-zone correction: what a deformation does over the Fresnel zone.

Frame and units of docs/physics.md (reflector frame, metres, SI fields); time convention
exp(+j w t), the phase convention of :mod:`raysim.optics.goedge` (PO's field is
Int F exp(-j k psi) dA with psi = k_i . r + |P - r|).

Why. The geometric wave (:mod:`raysim.optics.geowave`) answers to a surface deformation delta
as geometrical optics does: a phase 2 k delta along each ray and an amplitude change from the
curvature of delta (the transport of intensity behind the deformation-intensity equation). Wave
optics smooths every feature of delta smaller than the first Fresnel zone seen from the probe,
radius u_F = sqrt(lambda rho d / R) in the aperture (rho = F + z the ray's path from the
surface to the focus, d = rho - R its path to the sphere; 4.8 m at the vertex of the paper's
dish at 1 GHz), and its answer to a ripple of period Lambda has the opposite sign once Lambda
is below about u_F. On the paper's dish at 1 GHz, where Eq. 8's 1.7 m roll-off is such a
feature, the go+edge FA differs from PO's by 21 % of FA's RMS.

Method (derived for this engine from PO's integral, first order in delta). Moving the surface
by delta along z changes psi by q delta, q = d psi / dz, so to first order PO's field at P
changes by the fraction

    rho_wave(P) = -j k Int w q delta exp(-j k psi) dA / Int w exp(-j k psi) dA,

the integrals over the ideal paraboloid, with w a Gaussian window of standard deviation
sigma = :data:`WINDOW_SIGMA` u_F about the specular point s(P), times 1 / |P - r| (the
amplitude's spreading). The denominator is the window's stationary-phase weight, so the ratio
is the field's relative change without its absolute amplitude. For a delta smooth on the
Fresnel scale it tends to what geometrical optics gives (the phase of delta(s) and the term in
its second derivatives); for finer structure it is the Fresnel integral's. The geometric
wave's own first-order answer rho_go comes from a trace of the ideal surface plus eps delta
(:func:`linear_response`), and the correction swaps one for the other:

    E = E_geo(delta) + E_geo(0) (rho_wave - rho_go) + E_edge(delta).

So the geometric wave keeps its full (nonlinear) answer and only the first-order difference is
added. The window bounds the integral: wider windows tend to PO's first-order answer, at a
cost growing as sigma^2; the taper leaves a residual of its own, of order 1 / (2 pi
(sigma / u_F)^2) of the curvature term.

Measured (go+edge's FA difference from PO + PTD over FA's RMS, theta up to the rim's image
minus 2 deg, without and with the correction; ``benchmarks/bench_goedge.py --compare
--fresnel`` and ``tests/raysim/optics/test_fresnel.py``):

- the paper's dish, Eq. 8, 1 GHz (quadrant phi 0..90 deg on 1 deg cells): 21 % -> 1.9 %;
- the same at 3 GHz, E-plane cut: 5.2 % -> 1.3 %;
- a 10 m dish at 7.5 GHz with bumps of sigma 0.3 m (u_F = 0.49 m): 24 % -> 2.6 %;
- where the geometric wave already holds the correction's own residual shows: the same dish
  with bumps of sigma 0.8 m, 1.2 % -> 2.7 %; the 25 m dish at 10 GHz, Eq. 8 (about a radian of
  phase), 0.47 % -> 1.1 %.

Hence the correction is asked for (``simulate(..., fresnel=True)``, ``raysim simulate
--fresnel``), not the default: it pays where a deformation has structure finer than the
Fresnel zone (on the paper's dish below about 3 GHz).

Cost. The window is summed on a lattice whose step keeps the chirp exp(-j k psi) under
:data:`PHASE_STEP` rad per step at the window's edge; sigma and the step both scale as u_F,
so a window holds the same number of points at any frequency (about 4e4 for the defaults):
the cost grows with the sphere's points, not with f (about 10 s for 8100 points on two cores,
besides one more trace).

Limits. The specular points are those of the on-axis plane wave on the ideal paraboloid (the
line from the focus through P): other incidence, a reflector without a smooth surface
z = r^2 / 4F + delta (a loaded mesh), or no deformation get no correction (:func:`applies`
says why). Beyond the rim delta is continued by its value on the rim along each radius, so the
window adds no step there: the rim's own diffraction is the edge term's. First order in delta:
for deformations of many wavelengths the difference rho_wave - rho_go is no longer small.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from raysim.maps.sphere import SphereGrid
from raysim.optics import runtime
from raysim.optics.illumination import Illumination
from raysim.surface.deformation import Deformation, NoDeformation
from raysim.surface.mesh import Reflector

WINDOW_SIGMA = 2.0   # the window's standard deviation in Fresnel radii u_F
TRUNCATE = 3.0       # the window is summed out to TRUNCATE standard deviations
PHASE_STEP = 2.0     # rad: the chirp's largest phase step between lattice points
GO_EPS_PHASE = 1e-3  # rad: the largest phase of the eps-scaled trace (first order)
_AXIS = np.array([0.0, 0.0, -1.0])


@dataclass(frozen=True)
class FresnelCorrection:
    """The correction's field (n_theta, n_phi, 3) complex, V/m per V/m incident, its window
    and lattice, the points summed and the seconds spent."""

    dE: NDArray[np.complex128]
    window_sigma: float
    lattice_step_m: float
    points: int
    seconds: float

    def attrs(self) -> dict:
        return {"fresnel_correction": "first-order Fresnel-zone window (raysim.optics.fresnel)",
                "fresnel_window_sigma": self.window_sigma,
                "fresnel_lattice_step_m": self.lattice_step_m,
                "seconds_fresnel": self.seconds}


def applies(reflector: Reflector, wave: Illumination) -> str | None:
    """None when the correction applies to ``reflector`` under ``wave``, else why not."""
    if not np.allclose(wave.k_hat, _AXIS, rtol=0.0, atol=1e-12):
        return "the incident wave is not on the axis"
    if reflector.surface is None:
        return "the reflector has no smooth surface z = r^2 / 4F + delta"
    if reflector.from_file:
        return "the reflector is a loaded mesh (its departure has no continuation beyond the rim)"
    if isinstance(reflector.surface.deformation, NoDeformation):
        return "the reflector is not deformed"
    return None


def fresnel_radius(F: float, R: float, wavelength: float, theta: NDArray) -> NDArray:
    """u_F = sqrt(lambda rho (rho - R) / R) (m) of the ray reaching the sphere at ``theta``."""
    rho = 2.0 * F / (1.0 + np.cos(theta))
    return np.sqrt(wavelength * rho * np.maximum(rho - R, 0.0) / R)


def specular_points(F: float, points: NDArray) -> tuple[NDArray, NDArray]:
    """(s_xy (n, 2) m, theta (n,) rad): where the on-axis wave's reflected ray to each point
    (n, 3) leaves the ideal paraboloid (on the line from the focus through the point)."""
    d = points - np.array([0.0, 0.0, F])
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    theta = np.arccos(np.clip(-u[:, 2], -1.0, 1.0))
    rho = 2.0 * F / (1.0 + np.cos(theta))
    return rho[:, None] * u[:, :2], theta


def continued(deformation: Deformation, a: float, X: NDArray, Y: NDArray) -> NDArray:
    """delta at (X, Y) (m), continued beyond the rim r = a by its rim value along each radius."""
    r = np.hypot(X, Y)
    shrink = np.where(r > a, a * (1.0 - 1e-12) / np.maximum(r, 1e-300), 1.0)
    return np.asarray(deformation(X * shrink, Y * shrink), dtype=np.float64)


def window_response(deformed: Reflector, points: NDArray, R: float, wave: Illumination,
                    device: str | None = "cpu", sigma: float = WINDOW_SIGMA
                    ) -> tuple[NDArray[np.complex128], float]:
    """rho[delta] (n,) at ``points`` (n, 3) (m, dish frame) on the sphere of radius ``R`` (m)
    about the focus, for the window of ``sigma`` Fresnel radii, and the lattice step (m).
    ``deformed``: a paraboloid with a smooth deformed surface (:func:`applies`)."""
    from raysim.optics.kernels import fresnel as K

    wp = runtime.init()
    dev = runtime.resolve_device(device)
    F, a, k = float(deformed.F), 0.5 * float(deformed.D), float(wave.k)
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    s, theta = specular_points(F, pts)
    uF = fresnel_radius(F, R, wave.wavelength, theta)
    sig = sigma * uF
    # the chirp's phase gradient at distance u from s is about 2 pi u / u_F^2
    step_needed = PHASE_STEP * uF**2 / (2.0 * np.pi * TRUNCATE * sig)
    h = float(step_needed.min())
    stride = np.maximum(1, np.floor(step_needed / h)).astype(np.int32)
    n_half = np.ceil(TRUNCATE * sig / (stride * h)).astype(np.int32)
    extent = float(np.max(np.abs(s) + TRUNCATE * sig[:, None])) + 2.0 * h
    n = int(np.ceil(2.0 * extent / h)) + 1
    x0 = -0.5 * (n - 1) * h
    axis = x0 + h * np.arange(n)
    X, Y = np.meshgrid(axis, axis)
    delta = continued(deformed.surface.deformation, a, X, Y)
    num = wp.zeros(len(pts), dtype=wp.vec2d, device=dev)
    den = wp.zeros(len(pts), dtype=wp.vec2d, device=dev)
    runtime.launch(K.window_sums, len(pts), [
        wp.array(pts, dtype=wp.vec3d, device=dev), wp.array(s, dtype=wp.vec2d, device=dev),
        wp.array(sig, dtype=wp.float64, device=dev), wp.array(n_half, dtype=wp.int32, device=dev),
        wp.array(stride, dtype=wp.int32, device=dev),
        wp.array(delta, dtype=wp.float64, device=dev), x0, h, 4.0 * F, k, num, den],
        dev, min_chunk=64)
    nu, de = num.numpy(), den.numpy()
    return -1j * k * (nu[:, 0] + 1j * nu[:, 1]) / (de[:, 0] + 1j * de[:, 1]), h


def carries_wave(E_geo: NDArray[np.complex128]) -> NDArray[np.bool_]:
    """(n_theta, n_phi): the cells where the geometric wave E_geo (n_theta, n_phi, 3) is not
    (nearly) zero: inside the rim's image and not blocked."""
    power = np.sum(np.abs(E_geo) ** 2, axis=-1)
    return power > 1e-9 * power.max()


def linear_response(ideal: Reflector, deformation: Deformation, grid: SphereGrid,
                    wave: Illumination, E_geo_ideal: NDArray[np.complex128], subdivisions: int,
                    device: str | None = "cpu") -> NDArray[np.complex128]:
    """rho_go (n_theta, n_phi): the geometric wave's first-order relative change under
    ``deformation``, from a trace of ``ideal`` plus eps delta (eps: a largest phase of
    :data:`GO_EPS_PHASE`); zero where the ideal geometric wave is (nearly) zero."""
    from raysim.optics.geowave import trace_wave
    from raysim.surface.deformation import Scaled

    probe = np.linspace(-0.5 * ideal.D, 0.5 * ideal.D, 257)
    PX, PY = np.meshgrid(probe, probe)
    inside = np.hypot(PX, PY) <= 0.5 * ideal.D
    peak = float(np.max(np.abs(deformation(PX[inside], PY[inside]))))
    if not peak > 0.0:
        return np.zeros(E_geo_ideal.shape[:2], dtype=np.complex128)
    eps = GO_EPS_PHASE / (2.0 * wave.k * peak)
    small = ideal.deformed(Scaled(deformation, eps))
    focus = np.array([0.0, 0.0, ideal.F])
    E_eps = trace_wave(small, focus, grid.radius, wave, subdivisions, device).field(
        grid.points(ideal.F).reshape(-1, 3)).reshape(E_geo_ideal.shape)
    power = np.sum(np.abs(E_geo_ideal) ** 2, axis=-1)
    ok = carries_wave(E_geo_ideal)
    rho = np.zeros(power.shape, dtype=np.complex128)
    rho[ok] = np.sum(np.conj(E_geo_ideal) * (E_eps - E_geo_ideal), axis=-1)[ok] / (power[ok] * eps)
    return rho


def correction(ideal: Reflector, deformed: Reflector, grid: SphereGrid, wave: Illumination,
               E_geo_ideal: NDArray[np.complex128], subdivisions: int,
               device: str | None = "cpu", sigma: float = WINDOW_SIGMA) -> FresnelCorrection | None:
    """The field E_geo(0) (rho_wave - rho_go) to add to the deformed go+edge field (module
    docstring) at the cell centres of ``grid``, or None where :func:`applies` says no.
    ``E_geo_ideal`` (n_theta, n_phi, 3): the ideal reflector's geometric wave (cells where it
    is nearly zero, beyond the rim's image or blocked, get nothing); ``subdivisions``: the
    lattice order of the deformed field's trace (the same rays)."""
    if applies(deformed, wave) is not None:
        return None
    start = time.perf_counter()
    rho_go = linear_response(ideal, deformed.surface.deformation, grid, wave, E_geo_ideal,
                             subdivisions, device)
    lit = carries_wave(E_geo_ideal)
    points = grid.points(ideal.F)[lit]
    rho_wave = np.zeros(lit.shape, dtype=np.complex128)
    rho_wave[lit], h = window_response(deformed, points, grid.radius, wave, device, sigma)
    dE = E_geo_ideal * np.where(lit, rho_wave - rho_go, 0.0)[..., None]
    return FresnelCorrection(dE, float(sigma), h, int(lit.sum()), time.perf_counter() - start)
