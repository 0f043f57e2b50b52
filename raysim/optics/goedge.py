"""go+edge: the geometric reflected wave plus the diffracted waves of the free edges.

Frame and units of docs/physics.md (reflector frame, metres, SI fields); time convention
exp(+j w t), incident wave E_inc = e_hat exp(-j k k_hat . r), as in :mod:`raysim.optics.po`.
PO's cost grows with f^2 (surface samples); at the frequencies where that hurts, the PO
integral is, to leading order in 1/k, the geometric reflected wave plus a line integral along
the free edges (the rim, both sides of every panel gap, a central hole). Neither part costs
more as the frequency rises: the geometric wave comes from ray tubes
(:mod:`raysim.optics.geowave`), the edge waves from a line integral sampled a few times per
wavelength of its own phase (linear in f).

Formulation: equivalent edge currents integrated along the edges, with the geometric wave
from the tubes (the reflected wave, and -E_inc where a point lies in the reflector's shadow:
the shadow-forming wave, whose boundary the same edge integral smooths). Write PO's field as
Int_S F(r) exp(-j k psi(r)) dA with psi = k_i . r + |P - r| and F the dyadic Green's bracket
of the current 2 n x H_inc (:mod:`raysim.optics.kernels.radiation`).
For any tangent field v with (grad_s psi) . v = 1 / (-j k), the divergence theorem splits it
exactly into a boundary integral Int F exp(-j k psi) (v . nu) dl and an area remainder whose
only leading-order part is the stationary (specular) point, where div v has a delta. Gordon's
choice v ~ g / |g|^2 (g = grad_s psi = tangential part of k_i - R_hat; Gordon, IEEE Trans.
Antennas Propag. 23(4), 590-592, 1975, after the Maggi-Rubinowicz boundary wave; Miyamoto &
Wolf, J. Opt. Soc. Am. 52, 615-625, 1962) puts a delta of weight 2 pi there, which equals the
stationary-phase (GO) weight 2 pi / sqrt(det H) only when the surface Hessian H of psi is
isotropic: for the dish's anisotropic H the sum GO + boundary integral would jump at the
reflection boundary. Here v = M g / (-j k g^T M g) with M = adj H (derived for this engine): then
div v = 2 pi delta / sqrt(det H) exactly for a definite H, and the end-point current of an edge
element is

    p = J0 exp(-j k k_i . r) / (j k) * Int (M g . u) / (g^T M g) ds,   J0 = 2 n x h_hat / eta,

u the inward normal to the edge in the surface, the integral over the element's share of its
edge with g linear in s (g0 + s H t): in closed form, one arctangent (kernels module). On the
Keller cone (g . t = 0) it reduces to 1 / (j k (k_i - R_hat) . u), PO's end point as Michaeli
writes it; near a reflection boundary, where g vanishes at an edge point and the integrand is
a Lorentzian narrower than any fixed sampling, the closed form integrates it exactly, so the
jump of the edge integral there (2 pi / sqrt(det H) times the amplitude) cancels the jump of the
geometric wave: the sum is finite and continuous across the rim's image on the sphere, with the
Fresnel transition PO gives. H is computed per pair in float64 from the edge's surface
curvature and the distance to P (the near field: nothing assumes a far zone). Where H is not
definite, or worse conditioned than 4 (the kernels' BETA), M is adj of |H| with its small
eigenvalue raised to a quarter of the large: positive definite and continuous in H, so the
integrand stays finite and the field continuous in P. Exact cancellation at a reflection
boundary needs H at the specular point definite with condition number <= 4: no caustic between
the edge and P; on the probe sphere of a focusing dish with the paper's F / D it is 1.7 (H
definite at the rim image for the 110, 25 and 10 m dishes alike). Off the specular points the
choice of M changes the line integral at O(1/k) only (on the Keller cone every M gives
Michaeli's value); among the choices tried, |H| floored at 1/4 agreed best with PO. Added to it,
the fringe currents of :mod:`raysim.optics.ptd` (Michaeli's, the same kernels): PO end point
plus fringe is the half-plane's full diffraction (Ufimtsev, *Fundamentals of the Physical
Theory of Diffraction*, Wiley, 2007), radiated by the full dyadic Green's function. The
on-axis edge caustic, where all rim points add in phase, needs nothing special: it is a sum.

Why not UTD (Kouyoumjian & Pathak, Proc. IEEE 62(11), 1448-1461, 1974): it needs the
diffraction points of every edge for every field point (root finding on a curved rim and on
thousands of gap edges), the caustic correction near the axis (every sphere point near the
pole is in the rim's caustic region) and the reflected wavefront's curvatures in its
transition functions; equivalent currents share the PTD engine's fringe part and radiator,
stay finite at caustics by construction and evaluate any set of field points independently.

Validity and limits: leading order in 1/(k L) (L the distances and radii of curvature, metres),
so the difference from PO + PTD falls as the frequency rises. Measured: the disk's on-axis
edge wave (the caustic) within 1.5 % of PO's closed form at 0.3 GHz, 0.15 % at 3 GHz; the
half-plane (Sommerfeld) errors fall as (k rho)^-1.2 at normal incidence, (k rho)^-0.95 under
skew incidence, and for E across the edge within the reflection boundary's transition zone
they stay larger than PO + PTD's (3.7 % of the incident field at k rho = 100): the amplitude's
slope across the edge (PO's integrand in the near field) has a uniform end-point term of that
order that the leading-order form leaves out (a correction derived for the flat plate mended
the plate but not the dish, so it is not used). The geometric wave answers to a deformation's
fine structure as GO does, without the Fresnel smoothing wave optics applies to features
smaller than sqrt(lambda z) (z the reflected wave's path to its focus): on the paper's dish the
FA difference from PO + PTD is 21 % of FA's RMS at 1 GHz and 4.7 % at 3 GHz
(:mod:`raysim.optics.fresnel` adds that smoothing on request: 1.9 % at 1 GHz). Shadow boundaries
inside a surface (self-shadowing at oblique incidence) carry no edge term, and the shadow
test of the -E_inc wave follows the mesh's facets; a gap's two edges are isolated half-planes
(as in PTD). Obstacles in the beam (:mod:`raysim.optics.blockage`) block the geometric
wave's rays on either leg and the edge points they shade; the edges of their shadows on the
dish carry no edge term either, and their own field is not modelled. A block of field points
gives the same field bit for bit as
the whole sphere: the rays, tubes and edge points are planned for the whole sphere once
(:class:`GOEdge`), and each point's sums run in a fixed order.
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
from raysim.optics.geowave import GeometricWave, trace_wave
from raysim.optics.go import ray_subdivisions
from raysim.optics.illumination import ETA0, Illumination, Taper, incident_field
from raysim.optics.radiator import Radiator
from raysim.surface.edges import Edges, SpacingRule, edge_quadrature
from raysim.surface.mesh import Reflector

DEFAULT_POINTS_PER_WAVELENGTH = 4.0  # edge points per wavelength of the edge integrand's phase
MIN_PHASE_RATE = 0.15  # the integrand's phase rate along an edge is floored at this times k
RAYS_PER_DIAMETER = 400  # default ray spacing: D / this (m)
CURVATURE_STEP = 1e-3  # m: the finite-difference step of the surface normal at edge points
EDGE_THEORY = ("PO end-point currents (Hessian-weighted line integral, exact across reflection "
               "boundaries) plus Michaeli fringe currents, integrated along every free edge "
               "(raysim.optics.goedge)")


def edge_spacing_rule(wave: Illumination, centre: ArrayLike, radius: float,
                      points_per_wavelength: float = DEFAULT_POINTS_PER_WAVELENGTH) -> SpacingRule:
    """Spacing of the edge points for field points within ``radius`` (m) of ``centre``.

    The phase of the edge integrand advances at k |(k_i - R_hat) . t| along an edge; for a
    mesh edge of length l, R_hat spans the cone from its midpoint to the ball of radius
    ``radius`` + l / 2, which bounds |R_hat . t|. The spacing is the wavelength of that phase
    (never more than 1 / MIN_PHASE_RATE wavelengths) over ``points_per_wavelength``.
    """
    if not points_per_wavelength > 0:
        raise RaysimError(f"edge points per wavelength must be > 0, got {points_per_wavelength:g}")
    c = np.asarray(centre, dtype=np.float64)

    def rule(mid: NDArray, direction: NDArray, length: NDArray) -> NDArray:
        rel = c - mid
        dist = np.linalg.norm(rel, axis=1)
        reach = radius + 0.5 * length
        with np.errstate(divide="ignore", invalid="ignore"):
            cos_t = np.abs(np.sum(rel * direction, axis=1)) / dist
            alpha = np.arcsin(np.clip(reach / dist, 0.0, 1.0))
        along = np.where(dist <= reach, 1.0, np.cos(np.maximum(0.0, np.arccos(np.clip(cos_t, 0, 1)) - alpha)))
        rate = np.maximum(MIN_PHASE_RATE, np.abs(direction @ wave.k_hat) + along)
        return wave.wavelength / (points_per_wavelength * rate)

    return rule


def _curvature(reflector: Reflector, edges: Edges, t: NDArray, u: NDArray, y: NDArray) -> NDArray:
    """(N, 3) kappa_tt, kappa_tu, kappa_uu (1/m) of the surface at the edge points, positive
    where it curves towards the lit normal y (finite differences of the smooth surface's
    normal; zero for a mesh without one)."""
    surface = reflector.surface
    if surface is None:
        return np.zeros((len(edges), 3))
    panel = reflector.surface_panel(edges.face)
    p, h = edges.points, CURVATURE_STEP

    def slope_of_normal(e: NDArray) -> NDArray:
        a, b = p + h * e, p - h * e
        return (surface.normal(a[:, 0], a[:, 1], panel) - surface.normal(b[:, 0], b[:, 1], panel)) / (2 * h)

    dn_t, dn_u = slope_of_normal(t), slope_of_normal(u)
    side = np.sign(np.sum(surface.normal(p[:, 0], p[:, 1], panel) * y, axis=1))
    dot = lambda a, b: np.sum(a * b, axis=1)  # noqa: E731
    return side[:, None] * np.column_stack([-dot(dn_t, t), -0.5 * (dot(dn_t, u) + dot(dn_u, t)),
                                            -dot(dn_u, u)])


def diffraction_elements(reflector: Reflector, edges: Edges, wave: Illumination,
                         lit: NDArray[np.bool_] | None = None, taper: Taper | None = None,
                         fringe: bool = True) -> NDArray:
    """The ``(ROWS, N)`` layout of :mod:`raysim.optics.kernels.goedge` for the lit points of
    ``edges``: PTD's fringe rows, then the end-point moment (-eta / (4 pi)) J0 exp(-j k k_i . r),
    k_i, the curvature and the element's share of its edge (see the module docstring).
    ``fringe`` False keeps PO's end point alone (tests against PO's own closed forms)."""
    from raysim.optics import ptd

    keep = np.ones(len(edges), dtype=bool) if lit is None else np.asarray(lit, dtype=bool).copy()
    weight = np.ones(len(edges))
    if taper is not None:
        weight = np.asarray(taper(edges.points[:, 0], edges.points[:, 1]), dtype=np.float64)
        keep &= weight != 0
    rows = ptd.fringe_elements(edges, wave, keep, taper)[:, keep]
    if not fringe:
        rows[15:23] = 0.0  # the fringe coefficients CE, CH, CB, CM
    t, u, y = rows[3:6].T, rows[6:9].T, rows[9:12].T
    pts = edges.points[keep]
    phase = np.exp(-1j * wave.k * (pts @ wave.k_hat)) * weight[keep]

    J0 = (-ETA0 / (4.0 * np.pi)) * (2.0 * np.cross(y, wave.h_hat) / ETA0) * phase[:, None]
    share = edges.share[keep]
    flip = np.sum(t * edges.tangent[keep], axis=1) < 0
    s_lo = np.where(flip, -share[:, 1], share[:, 0])
    s_hi = np.where(flip, -share[:, 0], share[:, 1])
    kappa = _curvature(reflector, _subset(edges, keep), t, u, y)
    extra = np.vstack([J0.real.T, J0.imag.T, np.repeat(wave.k_hat[:, None], len(pts), axis=1),
                       kappa.T, s_lo, s_hi])
    return np.ascontiguousarray(np.vstack([rows, extra]))


def _subset(edges: Edges, keep: NDArray[np.bool_]) -> Edges:
    return Edges(*(None if getattr(edges, f) is None else getattr(edges, f)[keep]
                   for f in Edges.__dataclass_fields__))


@dataclass(frozen=True)
class GOEdgeField:
    """Field at a set of points (n, 3) complex, V/m per V/m incident: geometric and edge parts."""

    E_geo: NDArray[np.complex128]
    E_edge: NDArray[np.complex128]

    @property
    def E(self) -> NDArray[np.complex128]:
        return self.E_geo + self.E_edge


class GOEdge:
    """The go+edge engine prepared for one reflector, one wave and one probe sphere.

    The rays are traced and the edge elements planned for the whole sphere of ``grid`` here;
    :meth:`field` then evaluates any block of points on it, each point on its own (the same
    bits whatever the block). ``ray_spacing`` (m, default D / 400) sets the lattice order per
    face (at least ``subdivisions``); ``points_per_wavelength`` the edge sampling
    (:func:`edge_spacing_rule`); ``edges`` the free edges (``all`` or ``rim``).
    """

    def __init__(self, reflector: Reflector, grid: SphereGrid, wave: Illumination,
                 ray_spacing: float | None = None, subdivisions: int = 1,
                 points_per_wavelength: float = DEFAULT_POINTS_PER_WAVELENGTH, edges: str = "all",
                 device: str | None = "cpu", bvh: ReflectorBVH | None = None) -> None:
        from raysim.optics import ptd

        start = time.perf_counter()
        self.device = runtime.resolve_device(device)
        self.k = wave.k
        focus = np.array([0.0, 0.0, reflector.F])
        spacing = float(ray_spacing) if ray_spacing is not None else reflector.D / RAYS_PER_DIAMETER
        self.subdivisions = ray_subdivisions(reflector, spacing, subdivisions)
        bvh = bvh if bvh is not None else ReflectorBVH.build(reflector, self.device)
        self.bvh, self.incident = bvh, wave
        self.wave: GeometricWave = trace_wave(reflector, focus, grid.radius, wave, self.subdivisions,
                                              self.device, bvh)
        self.seconds_trace = time.perf_counter() - start
        quad = edge_quadrature(reflector, edge_spacing_rule(wave, focus, grid.radius, points_per_wavelength),
                               edges, n_min=1)
        lit = ptd.lit_points(reflector, quad, wave, self.device, bvh)
        self.elements = diffraction_elements(reflector, quad, wave, lit)
        self.n_edge_points, self.n_edge_lit = len(quad), int(lit.sum())
        self.seconds_edges = 0.0

    def field(self, points: ArrayLike) -> GOEdgeField:
        """Geometric and edge fields at ``points`` (n, 3) on the sphere (m, reflector frame).

        The geometric part is the reflected wave plus, at points in the reflector's shadow
        (another face meets the incident ray first), the shadow-forming wave -E_inc that
        cancels the incident one there. Call before the BVH (when shared) is refitted.
        """
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        E_geo = self.wave.field(pts)
        w = self.incident
        # the reflector's own shadow only: the obstacles' field (their shadow included) is not modelled
        shadow = ~self.bvh.lit(pts, w.k_hat, obstacles=False)
        if shadow.any():
            E_geo[shadow] -= incident_field(pts[shadow], w.k, w.k_hat, w.e_hat)
        start = time.perf_counter()
        radiator = Radiator(pts, self.k, self.device, block=1024)
        radiator.add_packed(self.elements, "diffraction")
        self.seconds_edges += time.perf_counter() - start
        return GOEdgeField(E_geo, radiator.field())


@dataclass(frozen=True)
class GOEdgeResult:
    """go+edge field on a sphere grid: ``E`` (n_theta, n_phi, 3) and its two parts."""

    E_geo: NDArray[np.complex128]
    E_edge: NDArray[np.complex128]
    n_rays: int
    n_tubes: int
    n_edge_points: int
    n_edge_lit: int
    subdivisions: int
    seconds_trace: float
    seconds_edges: float

    @property
    def E(self) -> NDArray[np.complex128]:
        return self.E_geo + self.E_edge


def sphere_field(reflector: Reflector, grid: SphereGrid, wave: Illumination,
                 ray_spacing: float | None = None, subdivisions: int = 1,
                 points_per_wavelength: float = DEFAULT_POINTS_PER_WAVELENGTH,
                 device: str | None = "cpu", bvh: ReflectorBVH | None = None) -> GOEdgeResult:
    """go+edge field of ``reflector`` at the cell centres of ``grid`` (every free edge)."""
    engine = GOEdge(reflector, grid, wave, ray_spacing, subdivisions, points_per_wavelength, "all",
                    device, bvh)
    shape = (grid.n_theta, grid.n_phi, 3)
    f = engine.field(grid.points(reflector.F).reshape(-1, 3))
    return GOEdgeResult(f.E_geo.reshape(shape), f.E_edge.reshape(shape), engine.wave.n_rays,
                        engine.wave.n_tubes, engine.n_edge_points, engine.n_edge_lit,
                        engine.subdivisions, engine.seconds_trace, engine.seconds_edges)


def edge_field(reflector: Reflector, points: ArrayLike, wave: Illumination, edges: str = "all",
               points_per_wavelength: float = DEFAULT_POINTS_PER_WAVELENGTH,
               device: str | None = "cpu", taper: Taper | None = None,
               curve: bool = True, fringe: bool = True) -> NDArray[np.complex128]:
    """The edge part alone (end point plus fringe) at any ``points`` (n, 3), m: E (n, 3).

    The edge sampling is planned for the ball around the points; ``taper`` weights the
    currents as PO's does, ``curve`` False keeps every edge straight, ``fringe`` False leaves
    PO's end point alone (tests).
    """
    from raysim.optics import ptd

    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    radius = float(np.linalg.norm(pts - centre, axis=1).max())
    dev = runtime.resolve_device(device)
    quad = edge_quadrature(reflector, edge_spacing_rule(wave, centre, radius, points_per_wavelength),
                           edges, n_min=1, curve=curve)
    lit = ptd.lit_points(reflector, quad, wave, dev)
    radiator = Radiator(pts, wave.k, dev, block=1024)
    radiator.add_packed(diffraction_elements(reflector, quad, wave, lit, taper, fringe), "diffraction")
    return radiator.field()
