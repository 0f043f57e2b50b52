"""Physical theory of diffraction: fringe (equivalent edge) currents on the reflector's free edges.

Frame and units of docs/physics.md (reflector frame, metres, SI fields); time convention
exp(+j w t), incident wave E_inc = e_hat exp(-j k k_hat . r) as in :mod:`raysim.optics.po`. PO
alone gets the current near an edge wrong: the exact current of the edge's wedge differs from
2 n x H_inc within a wavelength or so of the edge. PTD adds the field of that difference, the
fringe (non-uniform) current, as equivalent line currents I (electric, A) and M (magnetic, V)
along every lit free edge (:mod:`raysim.surface.edges`): the rim and the panel edges beside gaps. The
field adds to PO's by superposition.

Each edge is a thin plate (a half-plane, exterior wedge angle 2 pi). Edge frame: t along the
edge, x in the plate, normal to the edge and into it, y the plate's normal on the lit side
(t = x cross y). The wave travels along k_hat = (-sin b' cos p', -sin b' sin p', cos b') with
p' in (0, pi); the observation direction is s_hat = (sin b cos p, sin b sin p, cos b).

On the Keller cone (b = b') the problem is the 2-D half-plane with k_t = k sin b' for E_t and
H_t (soft and hard). Its exact diffraction coefficients, [sec((p - p')/2) -+ sec((p + p')/2)]
times -exp(-j pi/4) / (2 sqrt(2 pi k_t)) (Sommerfeld's solution; Balanis, *Advanced
Engineering Electromagnetics*, 2nd ed., the half-plane coefficients of the chapter on the
geometrical theory of diffraction), minus those of PO's current on the lit face (the end point
of its integral), -2 sin p' / (cos p + cos p') and 2 sin p / (cos p + cos p'), are the
half-plane's fringe coefficients (Ufimtsev's f^(1), g^(1): *Fundamentals of the Physical Theory
of Diffraction*, Wiley, 2007). With s = sin(p/2), c = cos(p'/2) and
cos p + cos p' = 2 (c - s)(c + s) they simplify to

    soft: 2 sin(p'/2) / (s + c),        hard: 2 cos(p/2) / (s + c),

finite at the shadow and reflection boundaries (s = c). A line current matched to the 2-D
field gives the equivalent currents on the cone,

    I = -j / (k eta sin^2 b') * 2 sin(p'/2) / (s + c) * E_t + 2 j cos b' / (k sin^2 b') * H_t,
    M = -j eta / (k sin^2 b') * 2 cos(p/2) / (s + c) * H_t,

where the H_t term of I cancels the cross-polar field PO's current radiates under skew
incidence (the exact solution has none). Off the cone we follow Michaeli (IEEE Trans.
Antennas Propag. 34(7), 912-918, 1986: the fringe current integrated along the ray coordinate
of the grazing diffracted ray, s_g = sin b' x + cos b' t, instead of normal to the edge, as in
Michaeli, ibid. 32(3), 252-258, 1984). Along that ray the integral is the 2-D transform of the
fringe current at the angle alpha with cos alpha = (s_hat . s_g - cos^2 b') / sin^2 b'
(<= 1, so s = sin(alpha/2) is real and vanishes only at s_hat = s_g), and its x and t
components T_x, T_t give I = T_t - T_x cot b cos p and M = -eta T_x sin p / sin b with
T_x = j H_t / (k sin b' s (s + c)) and T_t = I_cone(alpha) + T_x cot b' cos alpha. This is
the form :mod:`raysim.optics.kernels.ptd` evaluates for every (edge point, field point) pair,
with s_hat the direction between them, and radiates through the full dyadic Green's function:
the probe sphere is in the near field of the dish. The result is finite for every direction;
the one singular case Michaeli's form keeps (grazing incidence observed along the grazing
ray, Ufimtsev's singularity) is capped (see the kernels' module).

Everything above is derived here in the exp(+j w t) convention of docs/physics.md (no sign is
carried over from the references, whose conventions differ) and checked against Sommerfeld's
exact half-plane solution at normal and skew incidence (tests/raysim/test_ptd_halfplane.py).
Validity: each edge is an isolated half-plane. Two edges facing each other across a panel gap
much narrower than a wavelength are not: their fringe currents add, whatever the width.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.errors import RaysimError
from raysim.maps.sphere import SphereGrid
from raysim.optics import runtime
from raysim.optics.bvh import ReflectorBVH
from raysim.optics.fast.radiator import DEFAULT_TOL, make_radiator
from raysim.optics.illumination import ETA0, Illumination, Taper
from raysim.progress import Progress
from raysim.surface.edges import Edges, edge_quadrature
from raysim.surface.mesh import Reflector

DEFAULT_POINTS_PER_WAVELENGTH = 4.0
SIN_BETA_MIN = 1e-3  # incidence closer than this (rad) to the edge line: no fringe current


@dataclass(frozen=True)
class EdgeResult:
    """Fringe field of one reflector's edges: ``E`` (n, 3) complex, V/m per V/m incident."""

    E: NDArray[np.complex128]
    n_points: int
    n_lit: int
    pairs: int
    seconds: float


def fringe_elements(edges: Edges, wave: Illumination, lit: NDArray[np.bool_] | None = None,
                    taper: Taper | None = None) -> NDArray[np.float64]:
    """The kernel layout ``(ROWS, N)`` of :mod:`raysim.optics.kernels.ptd` for ``edges`` under
    ``wave``: edge frame, incidence angles and the complex coefficients (see :mod:`raysim.optics.ptd`).

    ``lit`` (N,) marks the points the wave reaches (all when None); ``taper(x, y)`` optionally
    weights each point (dimensionless, for tests).
    """
    from raysim.optics.kernels.ptd import ROWS

    k, k_hat, e_hat = wave.k, wave.k_hat, wave.e_hat
    n = edges.normal
    y = np.where((n @ k_hat < 0)[:, None], n, -n)  # the plate's normal on the lit side
    x = edges.inward - np.sum(edges.inward * y, axis=1, keepdims=True) * y
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    t = np.cross(x, y)
    cos_b = t @ k_hat
    sin_b = np.sqrt(np.maximum(1.0 - cos_b**2, 0.0))
    weight = edges.length.copy()
    if lit is not None:
        weight = np.where(lit, weight, 0.0)
    if taper is not None:
        weight = weight * np.asarray(taper(edges.points[:, 0], edges.points[:, 1]), dtype=np.float64)
    weight = np.where(sin_b > SIN_BETA_MIN, weight, 0.0)
    sin_b = np.maximum(sin_b, SIN_BETA_MIN)
    cos_p = np.clip(-(x @ k_hat) / sin_b, -1.0, 1.0)
    c = np.sqrt(0.5 * (1.0 + cos_p))  # cos(p'/2)
    sp = np.sqrt(0.5 * (1.0 - cos_p))  # sin(p'/2)
    phase = np.exp(-1j * k * (edges.points @ k_hat)) * weight
    E_t = (t @ e_hat) * phase  # E_t dl (V)
    H_t = (t @ np.cross(k_hat, e_hat)) / ETA0 * phase  # H_t dl (A)
    electric = -1j * k * ETA0 / (4.0 * np.pi)  # radiation prefactors (see raysim.optics.radiator)
    magnetic = 1j * k / (4.0 * np.pi)
    CE = electric * (-2j * sp * E_t / (k * ETA0 * sin_b**2))
    CH = electric * (2j * cos_b * H_t / (k * sin_b**2))
    T = 1j * H_t / (k * sin_b)
    CB = electric * T
    CM = magnetic * (-ETA0 * T)
    out = np.empty((ROWS, len(weight)))
    out[0:3], out[3:6], out[6:9], out[9:12] = edges.points.T, t.T, x.T, y.T
    out[12], out[13], out[14] = sin_b, cos_b, c
    for row, value in zip((15, 17, 19, 21), (CE, CH, CB, CM), strict=True):
        out[row], out[row + 1] = value.real, value.imag
    return out


def lit_points(reflector: Reflector, edges: Edges, wave: Illumination, device: str = "cpu",
               bvh: ReflectorBVH | None = None) -> NDArray:
    """(N,) bool: the edge points the plane wave reaches (the shadow test of every engine,
    :meth:`raysim.optics.bvh.ReflectorBVH.lit`, on each point's own face)."""
    if len(edges) == 0:
        return np.zeros(0, dtype=bool)
    bvh = bvh if bvh is not None else ReflectorBVH.build(reflector, device)
    return bvh.lit(edges.facet, wave.k_hat, edges.face)


def edge_field(reflector: Reflector, points: ArrayLike, wave: Illumination, edges: str = "rim",
               points_per_wavelength: float = DEFAULT_POINTS_PER_WAVELENGTH,
               device: str | None = "cpu", taper: Taper | None = None, curve: bool = True,
               progress: Progress | None = None, radiator: str = "direct", tol: float = DEFAULT_TOL,
               centre: ArrayLike | None = None) -> EdgeResult:
    """Fringe field of ``reflector``'s free edges at ``points`` (n, 3), m, reflector frame.

    ``edges`` is ``rim`` or ``all`` (rim, hole and panel-gap edges); ``points_per_wavelength``
    sets the Gauss points along the edges; ``taper(x, y)`` optionally weights the currents as
    PO's taper does; ``curve`` False keeps every edge straight; ``radiator``, ``tol``,
    ``centre``: as :func:`raysim.optics.fast.radiator.make_radiator`.
    """
    start = time.perf_counter()
    if not points_per_wavelength > 0:
        raise RaysimError(f"edge points per wavelength must be > 0, got {points_per_wavelength:g}")
    dev = runtime.resolve_device(device)
    quad = edge_quadrature(reflector, wave.wavelength / points_per_wavelength, edges, curve=curve)
    lit = lit_points(reflector, quad, wave, dev)
    rad = make_radiator(points, wave.k, dev, block=1024, radiator=radiator, tol=tol, centre=centre)
    rad.add_packed(fringe_elements(quad, wave, lit, taper), "fringe", progress)
    return EdgeResult(rad.field(), len(quad), int(lit.sum()), rad.pairs,
                      time.perf_counter() - start)


def sphere_edge_field(reflector: Reflector, grid: SphereGrid, wave: Illumination, edges: str = "rim",
                      points_per_wavelength: float = DEFAULT_POINTS_PER_WAVELENGTH,
                      device: str | None = "cpu", progress: Progress | None = None,
                      radiator: str = "direct", tol: float = DEFAULT_TOL) -> EdgeResult:
    """:func:`edge_field` at the cell centres of ``grid``; ``E`` shaped (n_theta, n_phi, 3)."""
    result = edge_field(reflector, grid.points(reflector.F).reshape(-1, 3), wave, edges,
                        points_per_wavelength, device, progress=progress, radiator=radiator, tol=tol,
                        centre=(0.0, 0.0, float(reflector.F)))
    return EdgeResult(result.E.reshape(grid.n_theta, grid.n_phi, 3), result.n_points, result.n_lit,
                      result.pairs, result.seconds)
