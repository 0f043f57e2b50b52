"""Quadrature of surface integrals over a reflector mesh: sample points and vector area elements.

Frame and units of docs/physics.md (reflector frame, metres). The integral of a field f over the
reflector surface S is approximated by sum_i f(r_i) . dS_i, where dS_i = n_i dA_i is the vector
area element (m^2) of sample i, n_i the unit normal towards the dish's front (+z side).

Where the reflector has a smooth surface z = h(x, y) (``Reflector.surface``), the surface is a
graph over the aperture plane, so every face is integrated over its projection on (x, y): the
sample lies at (x, y, h(x, y)) and n dA = (-dh/dx, -dh/dy, 1) dx dy. This is exact geometry: the
flat facets only define the domain. On raysim's own dishes, free mesh edges whose two ends lie
on one circle about the axis (the rim, a central hole, the inner and outer edges of a ring of
panels) are taken as arcs of that circle: the thin circular segment between chord and arc is
added (outer boundaries) or removed (inner boundaries) by a product Gauss rule in polar
coordinates; a mesh file's edges are the straight ones it has (``Reflector.arc_edges``).
Without a smooth surface (a bare triangulation) the samples lie on the flat facets, with the
facet's area and the interpolated vertex normal.

Each face carries a conical product rule of order n (n^2 points, exact to degree 2n - 1; the
conical product formulas of Stroud, *Approximate Calculation of Multiple Integrals*, 1971):
Gauss-Jacobi in the collapsed coordinate, Gauss-Legendre along the opposite edge. n is the face's longest edge
over ``spacing`` (so about n points span each edge); a face that would need more than
``n_max`` is split into m^2 congruent sub-triangles (its m-fold barycentric lattice) first.
The integrand on a reflector is smooth within a face, so the error falls exponentially with n:
a few large faces with high-order rules beat many small ones.

How fast the integrand oscillates is known before any sample exists. A PO current of a plane wave
travelling along k_i, radiated to a point P, has the phase -k (k_i . s + |P - s|) at the surface
point s, so its rate along the surface is k |t(k_i - u)|, u = (P - s) / |P - s| and t the
projection onto the surface's tangent plane. On a reflector that focuses the wave towards the
targets this is far below k: on a paraboloid lit along its axis, t(k_i) = t(u_F), u_F pointing
at the focus (the law of reflection), so for targets on a sphere of radius R about the focus the
rate is at most k R / |s - F| (0.18 k to 0.3 k on the paper's dish). Given the targets
(:class:`Targets`), :func:`plan` gives each face the fewest points whose Gauss rules follow
the phase its own rate (:func:`integrand_rate`) turns through across it
(:func:`integrand_orders`: high-order rules on a lattice of sub-triangles, each within
:func:`gauss_reach`), at least :data:`INTEGRAND_FLOOR` along a face, then reads what the surface
adds to its paraboloid face by face (:func:`surface_orders`), and never takes more points than
the samples per wavelength asked for: the integration grid follows the integrand's phase over
the observation region, not the wavelength alone.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
from numpy.typing import NDArray

from raysim.errors import RaysimError
from raysim.surface.deformation import NoDeformation
from raysim.surface.mesh import Reflector


@dataclass(frozen=True, eq=False)
class TriangleRule:
    """A rule on the reference triangle: barycentric points (P, 3), weights (P,) summing to 1
    (fractions of the triangle's area), exact for polynomials up to ``degree``."""

    bary: NDArray[np.float64]
    weights: NDArray[np.float64]
    degree: int

    @property
    def size(self) -> int:
        return len(self.weights)


@lru_cache(maxsize=16)
def conical_rule(n: int) -> TriangleRule:
    """The conical product rule with n^2 points (degree 2n - 1): Gauss-Jacobi in the
    collapsed coordinate s (weight s), Gauss-Legendre along t; x = A + s (B - A) + s t (C - B)."""
    from scipy.special import roots_jacobi

    xs, ws = roots_jacobi(n, 0.0, 1.0)  # weight (1 + x) on [-1, 1]
    s, w_s = 0.5 * (xs + 1.0), ws / ws.sum()
    t, w_t = gauss_legendre01(n)
    S, T = np.meshgrid(s, t, indexing="ij")
    bary = np.column_stack([1.0 - S.ravel(), (S * (1.0 - T)).ravel(), (S * T).ravel()])
    return TriangleRule(bary, np.outer(w_s, w_t).ravel(), 2 * n - 1)


@lru_cache(maxsize=64)
def lattice_rule(rule: TriangleRule, m: int) -> TriangleRule:
    """``rule`` applied on each of the m^2 sub-triangles of the triangle's m-fold lattice."""
    if m == 1:
        return rule
    corners = []
    for j in range(m):
        for i in range(m - j):
            corners.append(((i, j), (i + 1, j), (i, j + 1)))
            if i + j < m - 1:
                corners.append(((i + 1, j), (i + 1, j + 1), (i, j + 1)))
    bary = []
    for tri in corners:
        # lattice point (i, j) has barycentrics (1 - (i + j)/m, i/m, j/m)
        c = np.array([[1.0 - (i + j) / m, i / m, j / m] for i, j in tri])
        bary.append(rule.bary @ c)
    weights = np.tile(rule.weights / (m * m), len(corners))
    return TriangleRule(np.concatenate(bary), weights, rule.degree)


def gauss_legendre01(n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Gauss-Legendre nodes and weights on [0, 1] (weights sum to 1)."""
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


@lru_cache(maxsize=256)
def gauss_reach(n: int, tol: float) -> float:
    """The largest half-span omega (rad) up to which the n-point rules of the conical product
    (Gauss-Legendre, and Gauss-Jacobi with weight 1 + x) integrate exp(j omega x) over [-1, 1]
    within ``tol`` of the integral's scale (the weights' sum, 2): the phase, in radians, that a
    Gauss rule of n points can follow across half its interval. Gauss rules are exact to degree
    2n - 1 and exp(j omega x)'s Legendre coefficients fall off quickly past degree omega, so
    this grows about as 2n less a margin of order n^(1/3). Read off the rules against the
    exact integrals (2 sin w / w, and that plus 2 j (sin w - w cos w) / w^2 for the weight
    1 + x), on a grid of omega 0.1 rad apart (the error turns with a period of about pi), the
    last step then again 0.01 rad apart: the first grid point past ``tol``, less one."""
    from scipy.special import roots_jacobi

    def worst(omega: NDArray[np.float64]) -> NDArray[np.float64]:
        s, c = np.sin(omega), np.cos(omega)
        flat = 2.0 * s / omega
        exact = (flat, flat + 2j * (s - omega * c) / omega**2)
        out = np.zeros_like(omega)
        for (x, w), ref in zip((np.polynomial.legendre.leggauss(n), roots_jacobi(n, 0.0, 1.0)), exact,
                               strict=True):
            out = np.maximum(out, np.abs(np.exp(1j * np.outer(omega, x)) @ w - ref) / 2.0)
        return out

    coarse = np.arange(1, 40 * n + 1) * 0.1
    above = np.flatnonzero(worst(coarse) > tol)
    if not len(above):
        return float(coarse[-1])
    steps = np.arange(10 * int(above[0]) + 1, 10 * int(above[0]) + 11)  # its last step, in 0.01 rad
    past = np.flatnonzero(worst(steps * 0.01) > tol)
    last = int(steps[past[0]] if len(past) else steps[-1]) - 1
    return float(last * 0.01)


def integrand_orders(omega: NDArray[np.float64], tol: float | None = None, n_max: int | None = None,
                     floor: int | None = None) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """(m, n) per face for an integrand whose phase turns through 2 ``omega`` (rad, (F,))
    along the face's longest edge: the m-fold lattice of sub-triangles, each with the conical
    rule of order n in [``floor``, ``n_max``], with the fewest points m n along the edge
    such that omega / m is within :func:`gauss_reach` (n, ``tol``). Defaults:
    :data:`INTEGRAND_TOL`, :data:`INTEGRAND_N_MAX`, :data:`INTEGRAND_FLOOR` (None)."""
    tol = INTEGRAND_TOL if tol is None else tol
    n_max = INTEGRAND_N_MAX if n_max is None else n_max
    floor = INTEGRAND_FLOOR if floor is None else floor
    omega = np.asarray(omega, dtype=np.float64)
    if not np.all(np.isfinite(omega)) or np.any(omega < 0):
        raise RaysimError("integrand_orders: the phase per face must be finite and >= 0")
    best_m = np.zeros(omega.shape, dtype=np.int64)
    best_n = np.zeros(omega.shape, dtype=np.int64)
    for n in range(floor, n_max + 1):
        m = np.maximum(1, np.ceil(omega / gauss_reach(n, tol))).astype(np.int64)
        better = (best_n == 0) | (m * n < best_m * best_n)
        best_m, best_n = np.where(better, m, best_m), np.where(better, n, best_n)
        if np.all(m == 1):  # every face within one rule of n points: higher orders only add points
            break
    return best_m, best_n


def surface_orders(reflector: Reflector, m: NDArray[np.int64], n: NDArray[np.int64],
                   rate: NDArray[np.float64], k: float, cap: NDArray[np.int64]) -> NDArray[np.int64]:
    """The lattice folds m (F,) raised, face by face, until each face's rule (m, n) integrates
    what the surface adds to its paraboloid (the deformation, a loaded mesh's departure)
    within :data:`SURFACE_TOL`: the perturbation exp(j 2 k d) - 1 of the phase (d the added
    height, the reflected path changing by up to twice it), times a ramp of the face's rate
    ``rate`` (units of k) along x, along y and none, integrated with m and with 2m (the face's
    area 1); where the two differ by more, m doubles and the face is read again, until its
    points along an edge reach ``cap`` (the uniform rule's). Slopes and curvatures scale with
    a feature's height; what a rule must resolve scales with its width, so a narrow feature
    of micrometres is seen here and not by :func:`slope_allowance`. A surface that adds
    nothing keeps ``m``."""
    surface = reflector.surface
    if not _adds_to_paraboloid(reflector):
        return m
    corners = reflector.vertices[reflector.faces][..., :2]  # (F, 3, 2)
    panels = reflector.surface_panel(np.arange(len(corners)))
    m = np.asarray(m, dtype=np.int64).copy()
    base = int(n.max(initial=0)) + 1
    todo = np.flatnonzero(m * n < cap)
    for _ in range(SURFACE_DOUBLINGS):
        if not len(todo):
            break
        error = np.zeros(len(todo))
        key = m[todo] * base + n[todo]
        for value in np.unique(key):
            group = np.flatnonzero(key == value)
            mi, ni = divmod(int(value), base)
            coarse, fine = (lattice_rule(conical_rule(ni), f) for f in (mi, 2 * mi))
            per = max(1, SURFACE_POINTS // fine.size)
            for g0 in range(0, len(group), per):
                part = group[g0:g0 + per]
                faces = todo[part]
                panel = None if panels is None else panels[faces]
                error[part] = _perturbation_gap(surface, corners[faces], panel, rate[faces] * k, 2.0 * k,
                                                coarse, fine)
        todo = todo[error > SURFACE_TOL]
        m[todo] *= 2
        todo = todo[m[todo] * n[todo] < cap[todo]]
    return m


def _adds_to_paraboloid(reflector: Reflector) -> bool:
    """Whether ``reflector``'s smooth surface adds anything to its paraboloid (a deformation or
    a loaded mesh's departure); False for a bare triangulation."""
    surface = reflector.surface
    return surface is not None and (surface.departure is not None
                                    or not isinstance(surface.deformation, NoDeformation))


def _perturbation_gap(surface, corners: NDArray[np.float64], panels: NDArray[np.int64] | None,
                      ramp: NDArray[np.float64], scale: float, coarse: TriangleRule,
                      fine: TriangleRule) -> NDArray[np.float64]:
    """For faces with ``corners`` (f, 3, 2) m: the largest difference, over ramps of
    ``ramp`` (f,) rad/m along x, y and none, between the ``coarse`` and ``fine`` rules'
    integrals of (exp(j ``scale`` d) - 1) times the ramp, as a share of the face's area."""
    centre = corners.mean(axis=1)  # (f, 2)
    out = np.zeros(len(corners))
    results = []
    for rule in (coarse, fine):
        xy = np.einsum("pk,fkc->fpc", rule.bary, corners)  # (f, p, 2)
        panel = None if panels is None else np.repeat(panels[:, None], rule.size, axis=1)
        d = surface.added(xy[..., 0], xy[..., 1], panel)
        bump = np.expm1(1j * scale * d) * rule.weights  # (f, p)
        local = xy - centre[:, None, :]
        sums = [bump.sum(axis=1)]
        for axis in (0, 1):
            sums.append(np.einsum("fp,fp->f", bump, np.exp(1j * ramp[:, None] * local[..., axis])))
        results.append(sums)
    for a, b in zip(*results, strict=True):
        out = np.maximum(out, np.abs(a - b))
    return out


#: the largest error, relative to the integrand's amplitude, of each face's rule where it follows
#: the integrand (:func:`plan`): Gauss's error on exp(j omega x), omega the half of the phase the
#: integrand turns through across a sub-triangle (:func:`gauss_reach`)
INTEGRAND_TOL = 1e-9
#: the largest error, as a share of a face's area, of each face's rule on what the surface adds
#: to its paraboloid (:func:`surface_orders`)
SURFACE_TOL = 1e-8
#: the times a face's lattice is doubled at most for it, and the points read at once
SURFACE_DOUBLINGS = 6
SURFACE_POINTS = 2_000_000
#: the most Gauss points along a sub-triangle's edge where the rule follows the integrand: a
#: high order needs fewer points a period of the integrand (for 1e-9 about 5 at 10 points, 2.9
#: at 24, 2.1 at 64, 1.9 at 128; the limit is pi / 2), so a face's samples are (m n)^2 with n up
#: to this on an m-fold lattice. On the paper's dish (5 m faces) orders above 24 take the
#: samples at 3 GHz from 1.89 M to 1.11 M and at 12 GHz from 26.9 M to 11.5 M, with the field
#: unchanged to 2e-12 (benchmarks/bench_quadrature.py --n-max); only faces that many periods
#: long reach them (:func:`integrand_orders` stops at the order every face fits in)
INTEGRAND_N_MAX = 128
#: the least tilt allowance (:func:`slope_allowance`), units of k: 2 mrad of tilt
MIN_SLOPE_ALLOWANCE = 2.0**-8
#: the fewest Gauss points along a face's edge where the rule thins it: at three or four points
#: on a face (a small target ball, a low rate) the integrand's phase alone left 1e-5 of the
#: field from the faces' non-oscillating variation (the amplitude, the lifted surface's curvature)
INTEGRAND_FLOOR = 6
#: the most points :func:`surface_tilt` reads the surface's slopes at
MAX_TILT_POINTS = 2_000_000


@dataclass(frozen=True)
class Targets:
    """Where a surface integral is wanted: field points within ``radius`` (m) of ``centre``
    (m, reflector frame) for a plane wave travelling along ``k_hat`` (unit vector)."""

    centre: tuple[float, float, float]
    radius: float
    k_hat: tuple[float, float, float]


def targets_around(points: NDArray[np.float64], centre: tuple[float, float, float],
                   k_hat: NDArray[np.float64] | tuple[float, float, float]) -> Targets:
    """The :class:`Targets` of field ``points`` (n, 3) m: the ball about ``centre`` (m; the
    probe sphere's centre, the focus) that holds them all."""
    c = np.asarray(centre, dtype=np.float64)
    radius = float(np.max(np.linalg.norm(np.asarray(points, dtype=np.float64).reshape(-1, 3) - c, axis=1),
                          initial=0.0))
    return Targets((float(c[0]), float(c[1]), float(c[2])), radius,
                   tuple(float(v) for v in np.asarray(k_hat, dtype=np.float64)))  # type: ignore[arg-type]


def integrand_rate(reflector: Reflector, targets: Targets,
                   spacing: float | None = None) -> NDArray[np.float64]:
    """A bound (F,) on each face's integrand phase rate along the surface, in units of k:
    max over the face's corners and centroid of |t(k_i - u0)| + 2 sin(alpha / 2), u0 the
    direction from the point to the targets' centre and alpha = asin(R / distance) the half
    angle the targets' ball subtends (|u - u0| <= 2 sin(alpha / 2) for every target; t does
    not lengthen a vector). A point inside the ball gets 2 + |t(k_i)|, more than any rate.

    On a reflector with a smooth surface the points and normals are those of its paraboloid
    (focal length F), so a deformed reflector of the same triangulation, a refinement's next
    surface, a Jacobian's perturbed copy and a loaded mesh's ideal twin get the same samples;
    what tilts the surface away from it (a loaded mesh's departure, the deformation) is added
    as :func:`slope_allowance` of its steepest slope, found on a lattice of each face about
    ``spacing`` (m) apart (:func:`surface_tilt`), the same on every face. A bare triangulation
    uses its facets."""
    v = reflector.vertices[reflector.faces]  # (F, 3, 3)
    pts = np.concatenate([v, v.mean(axis=1, keepdims=True)], axis=1)  # corners and centroid
    allowance = 0.0
    surface = reflector.surface
    if surface is not None:
        x, y, F = pts[..., 0], pts[..., 1], float(surface.F)
        pts = np.stack([x, y, (x * x + y * y) / (4.0 * F)], axis=-1)
        normal = np.stack([-x / (2.0 * F), -y / (2.0 * F), np.ones_like(x)], axis=-1)
        allowance = slope_allowance(surface_tilt(reflector, spacing))
    else:
        cross = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        normal = np.broadcast_to(cross[:, None, :], pts.shape)
    normal = normal / np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-300)
    to_centre = np.asarray(targets.centre, dtype=np.float64) - pts
    distance = np.linalg.norm(to_centre, axis=-1)
    u0 = to_centre / np.maximum(distance, 1e-300)[..., None]
    w = np.asarray(targets.k_hat, dtype=np.float64) - u0
    tangential = np.linalg.norm(w - np.sum(w * normal, axis=-1, keepdims=True) * normal, axis=-1)
    inside = distance <= targets.radius
    alpha = np.arcsin(np.where(inside, 1.0, targets.radius / np.maximum(distance, 1e-300)))
    spread = np.where(inside, 2.0, 2.0 * np.sin(0.5 * alpha))
    return np.max(tangential + spread, axis=1) + allowance


def surface_tilt(reflector: Reflector, spacing: float | None = None) -> float:
    """The steepest slope (dimensionless) of what the smooth surface adds to its paraboloid (a
    loaded mesh's departure and the deformation), on a barycentric lattice of every face
    about ``spacing`` (m) apart (coarser where that would take more than
    :data:`MAX_TILT_POINTS` points; at least the corners, edge midpoints and centroid), so
    that a feature between a face's corners is seen; 0 for a bare paraboloid."""
    surface = reflector.surface
    if not _adds_to_paraboloid(reflector):
        return 0.0
    v = reflector.vertices[reflector.faces][..., :2]  # (F, 3, 2)
    length = np.linalg.norm(v[:, [1, 2, 0]] - v, axis=2).max(axis=1)
    a, b = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    area = 0.5 * float(np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum())
    step = max(float(spacing or 0.0), math.sqrt(2.0 * area / MAX_TILT_POINTS), 1e-300)
    order = np.clip(np.ceil(length / step), 2, 64).astype(np.int64)
    panels = reflector.surface_panel(np.arange(len(v)))
    steepest = 0.0
    for k in np.unique(order):
        faces = np.flatnonzero(order == k)
        i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
        keep = i + j <= k
        bary = np.column_stack([(k - i - j)[keep], i[keep], j[keep]]) / k
        bary = np.vstack([bary, [1 / 3, 1 / 3, 1 / 3]])
        per = max(1, MAX_TILT_POINTS // (4 * len(bary)))
        for f0 in range(0, len(faces), per):
            sel = faces[f0:f0 + per]
            xy = np.einsum("pk,fkc->fpc", bary, v[sel])  # (f, p, 2)
            panel = None if panels is None else np.repeat(panels[sel][:, None], len(bary), axis=1)
            gx, gy = surface.added_slope(xy[..., 0], xy[..., 1], panel)
            steepest = max(steepest, float(np.max(np.hypot(gx, gy), initial=0.0)))
    return steepest


def slope_allowance(tilt: float) -> float:
    """What tilting the surface by ``tilt`` (its steepest slope, dimensionless) can add to the
    integrand's rate (units of k): tilting the normal by e turns t(k_i - u), of length up
    to 2, by at most about 2 e; rounded up to a power of two, at least
    :data:`MIN_SLOPE_ALLOWANCE` (so deformations of millimetres over metres, the ones an
    inversion refines, all get the same samples)."""
    return max(MIN_SLOPE_ALLOWANCE, 2.0 ** math.ceil(math.log2(max(2.0 * tilt, 1e-300))))


@dataclass(frozen=True)
class Samples:
    """Quadrature samples of a set of faces (reflector frame, metres).

    ``points`` (N, 3) lie on the smooth surface (or the facets); ``area`` (N, 3) are the vector
    area elements n dA (m^2), n towards the dish's front; ``facet`` (N, 3) are points on the
    flat facets with the same footing, for the BVH's shadow test; ``face`` (N,) the face;
    ``on_arcs``: the samples of the circular segments beyond the faces' chords (whole faces'
    samples otherwise).
    """

    points: NDArray[np.float64]
    area: NDArray[np.float64]
    facet: NDArray[np.float64]
    face: NDArray[np.int64]
    on_arcs: bool = False

    def __len__(self) -> int:
        return len(self.face)


@dataclass(frozen=True)
class Arcs:
    """Free mesh edges lying on circles about the z axis, to be integrated as arcs.

    Edge e joins vertices ``b[e]`` and ``c[e]`` (both at radius ``radius[e]``) of face
    ``face[e]``; ``sign[e]`` is +1 when the face lies inside the circle (the circular segment
    between chord and arc is added) and -1 when it lies outside (the segment is removed).
    """

    b: NDArray[np.int64]
    c: NDArray[np.int64]
    face: NDArray[np.int64]
    radius: NDArray[np.float64]
    sign: NDArray[np.float64]

    def __len__(self) -> int:
        return len(self.face)


def free_edges(faces: NDArray[np.int64]) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """The mesh's free edges (used by one face only): the rim, hole and gap edges.

    Returns (b, c, a, face): the edge runs from vertex b to vertex c in the winding of
    ``face``, and a is that face's third vertex.
    """
    local = np.array([(0, 1, 2), (1, 2, 0), (2, 0, 1)])  # (b, c, opposite) per edge
    b = faces[:, local[:, 0]].ravel()
    c = faces[:, local[:, 1]].ravel()
    a = faces[:, local[:, 2]].ravel()
    face = np.repeat(np.arange(len(faces)), 3)
    key = np.sort(np.column_stack([b, c]), axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    free = counts[inverse.ravel()] == 1
    return b[free], c[free], a[free], face[free]


def boundary_arcs(reflector: Reflector, rtol: float = 1e-9) -> Arcs:
    """The free edges of ``reflector`` whose two ends lie at one radius from the z axis.

    Only meaningful for a reflector with a smooth surface: generated meshes put their panel
    rows on circles, so these are the rim and the ring edges. A straight radial gap edge has
    ends at different radii and stays straight.
    """
    r = np.hypot(reflector.vertices[:, 0], reflector.vertices[:, 1])
    b, c, a, face = free_edges(reflector.faces)
    rb, rc = r[b], r[c]
    sel = np.flatnonzero((rb > 0) & (np.abs(rb - rc) <= rtol * np.maximum(rb, rc)))
    radius = 0.5 * (rb[sel] + rc[sel])
    # the opposite vertex tells the side: inside the circle -> add the segment
    sign = np.where(r[a[sel]] < radius, 1.0, -1.0)
    return Arcs(b[sel], c[sel], face[sel], radius, sign)


@dataclass(frozen=True, eq=False)
class FaceQuadrature:
    """The quadrature plan of one reflector: per-face rule order and the boundary arcs.

    ``spacing`` (m) is the target distance between samples along a face's edges: a face of
    longest edge L gets the conical rule of order n = ceil(L / spacing), at least ``n_min``;
    beyond ``n_max`` it is split into m^2 sub-triangles with n = ceil(L / (m spacing)).
    ``face_spacing`` (F,) m, where given, is each face's own (never below ``spacing``, which
    stays the nominal one: shadow boundaries are resolved on it, :mod:`raysim.optics.shadow_edge`).
    Samples are produced in chunks of faces (:meth:`chunks`) so that a fine plan never holds
    all its samples at once.
    """

    reflector: Reflector
    spacing: float
    n_min: int = 3
    n_max: int = 10
    curve_rim: bool = True
    face_spacing: NDArray[np.float64] | None = None
    face_orders: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None

    @cached_property
    def spacings(self) -> NDArray[np.float64]:
        """Each face's sample spacing (F,) m."""
        if self.face_spacing is None:
            return np.full(len(self.reflector.faces), float(self.spacing))
        return np.maximum(np.asarray(self.face_spacing, dtype=np.float64), self.spacing)

    @cached_property
    def face_area(self) -> NDArray[np.float64]:
        """Area of each face (m^2): projected on (x, y) with a smooth surface, else 3-D."""
        v = self.reflector.vertices[self.reflector.faces]
        cross = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        if self.reflector.surface is not None:
            return 0.5 * np.abs(cross[:, 2])
        return 0.5 * np.linalg.norm(cross, axis=1)

    @cached_property
    def edge_length(self) -> NDArray[np.float64]:
        """Longest edge of each face (m), projected on (x, y) with a smooth surface."""
        v = self.reflector.vertices[self.reflector.faces]
        if self.reflector.surface is not None:
            v = v[..., :2]
        edges = v[:, [1, 2, 0]] - v
        return np.linalg.norm(edges, axis=2).max(axis=1)

    @cached_property
    def orders(self) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """(m, n) per face: m-fold lattice of sub-triangles, conical rule of order n on each
        (``face_orders`` where given, else from each face's spacing)."""
        if self.face_orders is not None:
            return self.face_orders
        return self.orders_for(self.edge_length, self.spacings)

    def orders_for(self, length: NDArray[np.float64], spacing: NDArray[np.float64] | float | None = None
                   ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """(m, n) for triangles of longest edge ``length`` (m, projected as :attr:`edge_length`):
        about one sample per ``spacing`` (m; default the nominal :attr:`spacing`) along it, n
        within [n_min, n_max] on an m-fold lattice."""
        step = self.spacing if spacing is None else spacing
        need = np.ceil(length / step)
        m = np.maximum(1, np.ceil(need / self.n_max)).astype(np.int64)
        n = np.ceil(length / (m * step))
        n = np.clip(n, self.n_min, self.n_max).astype(np.int64)
        return m, n

    @property
    def points_per_face(self) -> NDArray[np.int64]:
        m, n = self.orders
        return (m * n) ** 2

    @cached_property
    def arcs(self) -> Arcs:
        if not self.reflector.arc_edges or not self.curve_rim:
            empty = np.zeros(0, dtype=np.int64)
            return Arcs(empty, empty, empty, np.zeros(0), np.zeros(0))
        return boundary_arcs(self.reflector)

    @cached_property
    def arc_order(self) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Gauss points along each arc (as many as its face has along an edge, plus one) and
        across it (three, more where the segment is thicker than ``spacing``)."""
        v = self.reflector.vertices
        arcs = self.arcs
        length = np.linalg.norm(v[arcs.c, :2] - v[arcs.b, :2], axis=1)
        m, n = self.orders
        along = np.maximum(m[arcs.face] * n[arcs.face], np.ceil(length / self.spacings[arcs.face])) + 1
        sag = arcs.radius * (1.0 - np.cos(0.5 * length / np.maximum(arcs.radius, 1e-300)))
        # across the thin segment on the nominal spacing, three points at least: two cost the
        # field 1e-6 of its RMS on a 20 m dish at 3 GHz where three gave 2e-9, and 4.0e-7 on the
        # paper's dish at 3 GHz where three give 2.4e-10 (four 2.2e-12), for 0.2 % more samples
        across = np.maximum(3, np.ceil(2.0 * sag / self.spacing))
        return along.astype(np.int64), across.astype(np.int64)

    @property
    def n_samples(self) -> int:
        along, across = self.arc_order
        return int(np.sum(self.points_per_face) + np.sum(along * across))

    def chunks(self, max_points: int = 262_144) -> Iterator[Samples]:
        """Samples of consecutive face ranges (about ``max_points`` each), then of the arcs."""
        yield from (self._face_samples(s) for s in _ranges(self.points_per_face, max_points))
        if len(self.arcs):
            along, across = self.arc_order
            yield from (self._arc_samples(s) for s in _ranges(along * across, max_points))

    def samples(self) -> Samples:
        """All samples at once (small plans and tests)."""
        return concatenated(list(self.chunks(max_points=1 << 62)))

    # --- faces -------------------------------------------------------------------------------
    def _face_samples(self, faces: NDArray[np.int64]) -> Samples:
        refl = self.reflector
        parts: list[Samples] = []
        m_all, n_all = self.orders
        base = int(max(self.n_max, int(n_all.max(initial=0)))) + 1
        key = m_all[faces] * base + n_all[faces]
        for value in np.unique(key):
            sel = faces[key == value]
            rule = lattice_rule(conical_rule(int(value % base)), int(value // base))
            corners = refl.vertices[refl.faces[sel]]  # (F, 3, 3)
            facet = np.einsum("pk,fkc->fpc", rule.bary, corners).reshape(-1, 3)
            face = np.repeat(sel, rule.size)
            weight = (self.face_area[sel][:, None] * rule.weights[None, :]).reshape(-1)
            if refl.surface is not None:
                points, area = self._lift(facet[:, 0], facet[:, 1], face, weight)
            else:
                vn = refl.vertex_normals[refl.faces[sel]]
                nrm = np.einsum("pk,fkc->fpc", rule.bary, vn).reshape(-1, 3)
                nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
                points, area = facet, nrm * weight[:, None]
            parts.append(Samples(points, area, facet, face))
        return concatenated(parts)

    def at(self, face: NDArray[np.int64], bary: NDArray[np.float64],
           share: NDArray[np.float64]) -> Samples:
        """Samples at the barycentric points ``bary`` (N, 3) of faces ``face`` (N,), each
        weighing ``share`` (N,) of its face's area, lifted as the faces' own samples are: the
        samples of parts of faces (the lit part of a face an obstacle's shadow crosses)."""
        refl = self.reflector
        face = np.asarray(face, dtype=np.int64)
        facet = np.einsum("nk,nkc->nc", bary, refl.vertices[refl.faces[face]])
        weight = self.face_area[face] * share
        if refl.surface is not None:
            points, area = self._lift(facet[:, 0], facet[:, 1], face, weight)
        else:
            nrm = np.einsum("nk,nkc->nc", bary, refl.vertex_normals[refl.faces[face]])
            nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
            points, area = facet, nrm * weight[:, None]
        return Samples(points, area, facet, face)

    def _lift(self, x: NDArray, y: NDArray, face: NDArray, weight: NDArray) -> tuple[NDArray, NDArray]:
        """Points on the smooth surface over (x, y) and their vector areas for projected
        areas ``weight`` (m^2)."""
        refl = self.reflector
        panel = refl.surface_panel(face)
        z = refl.surface.height(x, y, panel)
        sx, sy = refl.surface.slope(x, y, panel)
        points = np.column_stack([x, y, z])
        area = np.column_stack([-sx * weight, -sy * weight, weight])
        return points, area

    # --- arcs --------------------------------------------------------------------------------
    def _arc_samples(self, index: NDArray[np.int64]) -> Samples:
        """Product Gauss rule over the circular segments between chord and arc, in polar
        coordinates (r, phi): phi along the arc, r from the chord out to the circle."""
        refl = self.reflector
        arcs = self.arcs
        along, across = self.arc_order
        v = refl.vertices
        parts = []
        pairs = along[index] * 1000 + across[index]
        for value in np.unique(pairs):
            e = index[pairs == value]
            xp, wp = gauss_legendre01(int(value // 1000))
            xr, wr = gauss_legendre01(int(value % 1000))
            b, c, rho = v[arcs.b[e]], v[arcs.c[e]], arcs.radius[e]
            phi_b = np.arctan2(b[:, 1], b[:, 0])
            dphi = np.angle(np.exp(1j * (np.arctan2(c[:, 1], c[:, 0]) - phi_b)))
            mid = phi_b + 0.5 * dphi
            phi = phi_b[:, None] + xp[None, :] * dphi[:, None]  # (E, P)
            r_chord = (rho * np.cos(0.5 * dphi))[:, None] / np.cos(phi - mid[:, None])
            # polar area element r dr dphi over r in [r_chord, rho], phi along the arc
            r = r_chord[..., None] + xr * (rho[:, None] - r_chord)[..., None]  # (E, P, Q)
            w = ((np.abs(dphi) * arcs.sign[e])[:, None] * wp[None, :] * (rho[:, None] - r_chord))
            w = w[..., None] * wr * r
            phi3 = np.broadcast_to(phi[..., None], r.shape)
            x, y = (r * np.cos(phi3)).ravel(), (r * np.sin(phi3)).ravel()
            face = np.repeat(arcs.face[e], len(xp) * len(xr))
            points, area = self._lift(x, y, face, w.ravel())
            # the shadow test looks at the facet just inside the chord, at the same phi
            opposite = v[refl.faces[arcs.face[e]]].sum(axis=1) - b - c
            on_chord = b[:, None, :] + xp[None, :, None] * (c - b)[:, None, :]
            inside = on_chord + 1e-3 * (opposite[:, None, :] - on_chord)
            facet = np.repeat(inside.reshape(-1, 3), len(xr), axis=0)
            parts.append(Samples(points, area, facet, face, on_arcs=True))
        return concatenated(parts)


def _ranges(counts: NDArray[np.int64], max_points: int) -> Iterator[NDArray[np.int64]]:
    """Consecutive index ranges whose counts add up to about ``max_points`` (at least one)."""
    cum = np.cumsum(counts)
    start = 0
    while start < len(counts):
        base = cum[start - 1] if start else 0
        stop = int(np.searchsorted(cum, base + max_points, side="right"))
        stop = min(max(stop, start + 1), len(counts))
        yield np.arange(start, stop)
        start = stop


def concatenated(parts: list[Samples]) -> Samples:
    """The samples of ``parts`` (at least one) as one set."""
    if len(parts) == 1:
        return parts[0]
    return Samples(*(np.concatenate([getattr(p, f) for p in parts])
                     for f in ("points", "area", "facet", "face")),
                   on_arcs=bool(parts) and all(p.on_arcs for p in parts))


def plan(reflector: Reflector, wavelength: float, samples_per_wavelength: float,
         targets: Targets | None = None) -> FaceQuadrature:
    """The quadrature plan for ``reflector`` at ``wavelength`` (m): about
    ``samples_per_wavelength`` Gauss points per wavelength along every face edge; with
    ``targets``, fewer where the integrand oscillates slower than that: each face the fewest
    points along its edge whose Gauss rules follow the phase its own rate
    (:func:`integrand_rate`) turns through across it within :data:`INTEGRAND_TOL`
    (:func:`integrand_orders`), at least :data:`INTEGRAND_FLOOR`; never more in all than the
    uniform rule's (where its own rules would take more, each face is held to the uniform
    rule's points)."""
    if not samples_per_wavelength > 0:
        raise RaysimError(f"samples per wavelength must be > 0, got {samples_per_wavelength}")
    spacing = wavelength / samples_per_wavelength
    quadrature = FaceQuadrature(reflector, spacing)
    if targets is None:
        return quadrature
    length = quadrature.edge_length
    k = 2.0 * np.pi / wavelength
    rate = integrand_rate(reflector, targets, spacing)
    # half the phase the integrand turns through along the face's longest edge
    m, n = integrand_orders(0.5 * k * length * rate)
    m_u, n_u = quadrature.orders
    m = surface_orders(reflector, m, n, rate, k, m_u * n_u)
    # a face the integrand turns on faster than the uniform rule follows (a wave far off the
    # axis) keeps its own rule while the whole stays within the uniform rule's samples: 15 deg
    # off axis on the paper's dish at 3 GHz, the uniform rule on those few faces left 4.8e-6 of
    # the field, their own rules 4e-11, for 0.2 % more samples. Beyond that total (targets
    # reaching the surface) every face is held to the uniform rule's points
    if np.sum(np.square(m * n)) > np.sum(np.square(m_u * n_u)):
        uniform = m_u * n_u <= m * n
        m, n = np.where(uniform, m_u, m), np.where(uniform, n_u, n)
    face_spacing = np.maximum(length / (m * n), spacing)
    return FaceQuadrature(reflector, spacing, face_spacing=face_spacing, face_orders=(m, n))
