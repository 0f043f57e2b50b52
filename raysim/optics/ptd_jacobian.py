"""The rim's PTD fringe field linearised in the surface: JVP and adjoint of :mod:`raysim.optics.ptd`.

Frame and units of docs/physics.md; time convention exp(+j w t). On a reflector with a smooth
surface z = h(x, y) the rim's Gauss points keep their footprints (x_e, y_e) on the circle
r = D/2 (:func:`raysim.surface.edges.edge_quadrature`); a perturbation dh moves each along z by
dz_e and changes the slopes there by (dh_x, dh_y), which turn the edge's tangent (its rise
h_x dx + h_y dy along the footprint's direction), its plate normal (-h_x, -h_y, 1) / norm,
the in-plate direction and the arc length, and with the position the incident phase of the
fringe coefficients. :func:`perturbed_edges` rebuilds the edge frame from (dz, dh_x, dh_y)
exactly as the quadrature builds it from the surface.

The fringe kernel (Michaeli's form, :mod:`raysim.optics.kernels.ptd`) is a long smooth function
of an element's 23 rows. Its derivative along a perturbation is taken at the element level by
a central difference of the element's own parameters (step 1e-6 m in z and 1e-6 in the
slopes: the error, (k eps)^2 / 6 from the step and 1e-16 / (k eps) from rounding, is below
1e-10 of the derivative up to several GHz), never by re-running the engine: the JVP radiates
the two shifted element sets (two fringe radiations, a few per cent of a PO one); the adjoint
sums each element's response over the field points in the transposed kernel
(:func:`raysim.optics.kernels.radiation.adjoint_kernel`), for the six shifted copies at once.
The lit set is the state's.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.errors import RaysimError
from raysim.optics import runtime
from raysim.optics.fast.radiator import DEFAULT_TOL, make_radiator
from raysim.optics.illumination import Illumination
from raysim.optics.ptd import DEFAULT_POINTS_PER_WAVELENGTH, fringe_elements, lit_points
from raysim.surface.edges import Edges, edge_quadrature
from raysim.surface.mesh import Reflector

EPS = 1e-6  # element-level step: m in z, dimensionless in the slopes
#: the fast transposed sum runs at this fraction of the caller's tolerance: the central
#: differences of the shifted copies are interpolated as a field of their own, and the fringe
#: coefficients' change with the slopes is less smooth over the sphere than the field (measured,
#: 10 m dish at 1 GHz: gradients err 2e-6 to 8e-6 at a 1e-6 field tolerance, 1e-7 to 5e-7 at 1e-8)
FAST_TOL_FACTOR = 1e-2


@dataclass(frozen=True)
class EdgeState:
    """The rim's quadrature at one surface state: edges, their lit flags, the footprint
    direction q (n, 2: the tangent's x, y over the tangent's length) and the slopes."""

    edges: Edges
    lit: NDArray[np.bool_]
    q: NDArray[np.float64]
    hx: NDArray[np.float64]
    hy: NDArray[np.float64]

    @property
    def x(self) -> NDArray[np.float64]:
        return self.edges.points[:, 0]

    @property
    def y(self) -> NDArray[np.float64]:
        return self.edges.points[:, 1]


def edge_state(reflector: Reflector, wave: Illumination, edges: str = "rim",
               points_per_wavelength: float = DEFAULT_POINTS_PER_WAVELENGTH,
               device: str | None = "cpu") -> EdgeState:
    """The edge quadrature of :func:`raysim.optics.ptd.edge_field` on ``reflector``."""
    quad = edge_quadrature(reflector, wave.wavelength / points_per_wavelength, edges)
    lit = lit_points(reflector, quad, wave, runtime.resolve_device(device))
    n = quad.normal
    return EdgeState(quad, lit, quad.tangent[:, :2].copy(), -n[:, 0] / n[:, 2], -n[:, 1] / n[:, 2])


def perturbed_edges(state: EdgeState, dz, dhx, dhy) -> Edges:
    """The edges of the surface h + dh: points moved by dz, frames from the slopes + (dhx, dhy)."""
    e = state.edges
    hx, hy = state.hx + dhx, state.hy + dhy
    deriv = np.column_stack([state.q, hx * state.q[:, 0] + hy * state.q[:, 1]])
    stretch = np.linalg.norm(deriv, axis=1)
    tangent = deriv / stretch[:, None]
    normal = np.column_stack([-hx, -hy, np.ones_like(hx)])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    inward = np.cross(normal, tangent)
    inward /= np.linalg.norm(inward, axis=1, keepdims=True)
    inward *= np.where(np.sum(inward * e.inward, axis=1) < 0, -1.0, 1.0)[:, None]
    points = e.points + np.column_stack([np.zeros_like(hx), np.zeros_like(hx), dz])
    return replace(e, points=points, tangent=tangent, normal=normal, inward=inward,
                   length=e.length * stretch)


def _rows(state: EdgeState, wave: Illumination, dz, dhx, dhy) -> NDArray[np.float64]:
    return fringe_elements(perturbed_edges(state, dz, dhx, dhy), wave, state.lit)


def jvp(state: EdgeState, wave: Illumination, points: ArrayLike, dz: ArrayLike, dhx: ArrayLike,
        dhy: ArrayLike, device: str | None = "cpu", radiator: str = "direct", tol: float = DEFAULT_TOL,
        centre: ArrayLike | None = None, force: bool = False) -> NDArray[np.complex128]:
    """dE (n, 3) of the fringe field at ``points`` for per-point dz (m) and slope changes.

    ``radiator="fast"`` with ``centre`` (the sphere's centre, m): both copies of the central
    difference summed multilevel on one tree (``plans`` of
    :class:`raysim.optics.fast.radiator.FastRadiator`), so the sums' errors cancel in the
    difference as they do in the transposed sum, at ``tol`` times :data:`FAST_TOL_FACTOR` for
    the same reason as :func:`vjp`; ``force`` as
    :func:`raysim.optics.fast.radiator.make_radiator`.
    """
    dz, dhx, dhy = (np.asarray(a, dtype=np.float64) for a in (dz, dhx, dhy))
    size = max(float(np.max(np.abs(np.concatenate([dz, dhx, dhy])), initial=0.0)), 1e-300)
    t = EPS / size
    plans: dict = {}
    fields = []
    radiator, sum_tol = _sums(radiator, tol)
    for sign in (1.0, -1.0):
        rad = make_radiator(points, wave.k, device, block=1024, radiator=radiator, tol=sum_tol,
                            centre=centre, force=force, plans=plans)
        rad.add_packed(_rows(state, wave, sign * t * dz, sign * t * dhx, sign * t * dhy), "fringe")
        fields.append(rad.field())
    return (fields[0] - fields[1]) / (2.0 * t)


def _sums(radiator: str, tol: float) -> tuple[str, float]:
    """The radiator and the tolerance of the sums of a Jacobian held to ``tol``: the sums
    :data:`FAST_TOL_FACTOR` finer, and the direct sum where that is finer than the fast one's
    finest (a ``tol`` below 1e-10 was refused as "got 1e-13", naming no value given).
    RaysimError naming ``tol`` when it is not a radiator tolerance."""
    from raysim.optics.fast.radiator import MIN_TOL, tol_problem

    problem = tol_problem(tol)
    if problem:
        raise RaysimError(problem)
    finer = tol * FAST_TOL_FACTOR
    return ("direct", tol) if finer < MIN_TOL else (radiator, finer)


def vjp(state: EdgeState, wave: Illumination, points: ArrayLike, c: ArrayLike,
        device: str | None = "cpu", block: int = 2048, radiator: str = "direct",
        tol: float = DEFAULT_TOL, centre: ArrayLike | None = None, force: bool = False,
        info: dict | None = None) -> tuple[NDArray, NDArray, NDArray]:
    """Gradients (n_edge_points,) of Re sum_P conj(c(P)) . dE(P) in dz, dh_x and dh_y.

    ``radiator="fast"`` with ``centre`` (the sphere's centre, m): the six shifted copies' sums
    by the transposed multilevel sum (:func:`raysim.optics.fast.adjoint.transposed_sum`,
    at ``tol`` times :data:`FAST_TOL_FACTOR`, so that the gradients keep ``tol``), where its
    rules choose it; otherwise direct. ``info``, when given, receives ``method``.
    """
    from raysim.optics.fast.radiator import RADIATORS
    from raysim.optics.kernels import po_derivative, radiation

    if radiator not in RADIATORS:
        raise RaysimError(f"unknown radiator {radiator!r}: use one of {', '.join(RADIATORS)}")
    radiator, sum_tol = _sums(radiator, tol)
    wp = runtime.init()
    dev = runtime.resolve_device(device)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    b = np.conj(np.asarray(c, dtype=np.complex128).reshape(-1, 3))  # fringe prefactor is 1
    n = len(state.edges)
    zero = np.zeros(n)
    shifts = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            step = [zero, zero, zero]
            step[axis] = np.full(n, sign * EPS)
            shifts.append(_rows(state, wave, *step))
    rows = np.ascontiguousarray(np.hstack(shifts))
    acc = None
    if radiator == "fast" and centre is not None:
        from raysim.optics.fast import adjoint

        acc = adjoint.transposed_sum(po_derivative.segments_fringe_adjoint, rows, pts, b, wave.k,
                                     centre, dev, tol=sum_tol, force=force, info=info,
                                     kind="fringe")
    if acc is None:
        if info is not None:
            info["method"] = "direct"
        src = wp.array(rows, dtype=wp.float64, device=dev)
        field_arr = wp.array(np.ascontiguousarray(np.vstack([pts.T, b.real.T, b.imag.T])),
                             dtype=wp.float64, device=dev)
        out = wp.zeros((8, 6 * n), dtype=wp.float64, device=dev)
        table = wp.array(radiation.cis_table(), dtype=wp.vec2d, device=dev)
        for begin in range(0, len(pts), block):
            runtime.launch(po_derivative.fringe_adjoint, 6 * n,
                           [field_arr, src, begin, min(begin + block, len(pts)), wave.k,
                            1.0 / wave.k, table, out], dev, min_chunk=16)
        acc = out.numpy()
    first = acc[0].reshape(6, n)
    return tuple((first[2 * a] - first[2 * a + 1]) / (2.0 * EPS) for a in range(3))
