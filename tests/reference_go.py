"""Independent geometric-optics reference for tests: exact GO intensity on the probe sphere.

Frame (docs/physics.md): vertex at the origin, axis +z, focus C = (0, 0, F); lengths in metres,
angles in radians. The reflector is the smooth surface z = r^2 / (4F) + delta(x, y), lit by a
plane wave travelling along -z with unit intensity. The probe sphere has radius R around C.

This module shares no code with ``raysim.optics.go`` or ``solver``: it inverts the ray map point by
point instead of tracing tubes. For every sphere direction (theta, phi) a vectorised Newton
iteration finds the aperture point (x, y) whose reflected ray reaches that sphere point. Power
conservation along the ray tube then gives the intensity relative to the incident wave,

    I = dA_aperture / dA_sphere = 1 / |dS/dx x dS/dy|,

with S(x, y) the entering intersection of the reflected ray with the sphere, differentiated by
central differences. On the ideal paraboloid this is (rho / R)^2, rho = 2F / (1 + cos theta).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from raysim.maps.fieldmap import fieldmap
from raysim.maps.sphere import SphereGrid

Deformation = Callable[[NDArray[np.float64], NDArray[np.float64]], NDArray[np.float64]]

SLOPE_STEP = 1e-4     # m, central-difference step for the slopes of delta without .gradient
JACOBIAN_STEP = 1e-3  # m, central-difference step of the ray map (x, y) -> S


def slopes(x, y, F: float, delta: Deformation | None):
    """Surface height f (m) and slopes (f_x, f_y) of z = r^2/(4F) + delta at (x, y)."""
    f = (x * x + y * y) / (4.0 * F)
    fx = x / (2.0 * F)
    fy = y / (2.0 * F)
    if delta is None:
        return f, fx, fy
    f = f + delta(x, y)
    if hasattr(delta, "gradient"):
        dx, dy = delta.gradient(x, y)
    else:
        e = SLOPE_STEP
        dx = (delta(x + e, y) - delta(x - e, y)) / (2.0 * e)
        dy = (delta(x, y + e) - delta(x, y - e)) / (2.0 * e)
    return f, fx + dx, fy + dy


def sphere_hit(x, y, F: float, R: float, delta: Deformation | None = None):
    """Point S (..., 3) where the ray reflected at aperture point (x, y) enters the sphere (m)."""
    f, fx, fy = slopes(x, y, F, delta)
    norm = np.sqrt(1.0 + fx * fx + fy * fy)
    n = np.stack([-fx / norm, -fy / norm, 1.0 / norm], axis=-1)   # unit normal, towards +z
    incident = np.array([0.0, 0.0, -1.0])
    out = incident - 2.0 * (n @ incident)[..., None] * n           # mirror reflection
    w = np.stack([x, y, f - F], axis=-1)                             # surface point - focus
    ow = np.sum(out * w, axis=-1)
    disc = ow * ow - (np.sum(w * w, axis=-1) - R * R)
    t = -ow - np.sqrt(disc)                                          # nearer root: entering
    return np.stack([x, y, f], axis=-1) + t[..., None] * out


def plane_coordinates(S, F: float):
    """Ideal-mapping aperture coordinates of sphere points: 2F (u_x, u_y) / (1 - u_z) (m).

    u is the unit vector from the focus to S; on the ideal reflector this returns the (x, y)
    the ray came from (r = 2F tan(theta / 2)), with no singularity at theta = 0.
    """
    u = S - np.array([0.0, 0.0, F])
    u = u / np.linalg.norm(u, axis=-1, keepdims=True)
    scale = 2.0 * F / (1.0 - u[..., 2])
    return u[..., 0] * scale, u[..., 1] * scale


def preimage(theta, phi, F: float, R: float, delta: Deformation | None = None,
             tol: float = 1e-11, max_iter: int = 30):
    """Aperture points (x, y) (m) whose reflected rays reach sphere directions (theta, phi).

    Vectorised Newton iteration on the ideal-mapping coordinates, started from the ideal
    mapping r = 2F tan(theta / 2). Points that do not converge (no real intersection, or delta
    undefined there) come back as NaN.
    """
    theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
    shape = theta.shape
    theta, phi = theta.ravel(), phi.ravel()
    r_ideal = 2.0 * F * np.tan(0.5 * theta)
    qx, qy = r_ideal * np.cos(phi), r_ideal * np.sin(phi)
    x, y = qx.copy(), qy.copy()
    h = JACOBIAN_STEP
    active = np.ones(x.shape, dtype=bool)
    for _ in range(max_iter):
        xa, ya = x[active], y[active]
        px, py = plane_coordinates(sphere_hit(xa, ya, F, R, delta), F)
        rx, ry = px - qx[active], py - qy[active]
        ax, ay = plane_coordinates(sphere_hit(xa + h, ya, F, R, delta), F)
        bx, by = plane_coordinates(sphere_hit(xa - h, ya, F, R, delta), F)
        cx, cy = plane_coordinates(sphere_hit(xa, ya + h, F, R, delta), F)
        dx, dy = plane_coordinates(sphere_hit(xa, ya - h, F, R, delta), F)
        j11, j21 = (ax - bx) / (2 * h), (ay - by) / (2 * h)
        j12, j22 = (cx - dx) / (2 * h), (cy - dy) / (2 * h)
        det = j11 * j22 - j12 * j21
        sx = (j22 * rx - j12 * ry) / det
        sy = (j11 * ry - j21 * rx) / det
        x[active] = xa - sx
        y[active] = ya - sy
        step = np.hypot(sx, sy)
        done = (step < tol) | ~np.isfinite(step)
        idx = np.flatnonzero(active)
        active[idx[done]] = False
        if not active.any():
            break
    bad = active | ~np.isfinite(x) | ~np.isfinite(y)
    x[bad] = np.nan
    y[bad] = np.nan
    return x.reshape(shape), y.reshape(shape)


def intensity_at(theta, phi, F: float, R: float, delta: Deformation | None = None,
                 D: float | None = None):
    """GO intensity (relative to the incident wave) at sphere directions (theta, phi).

    Point values; with ``D`` given, directions whose ray comes from beyond the rim r = D/2
    (or from nowhere) get 0.
    """
    x, y = preimage(theta, phi, F, R, delta)
    h = JACOBIAN_STEP
    sx = (sphere_hit(x + h, y, F, R, delta) - sphere_hit(x - h, y, F, R, delta)) / (2 * h)
    sy = (sphere_hit(x, y + h, F, R, delta) - sphere_hit(x, y - h, F, R, delta)) / (2 * h)
    value = 1.0 / np.linalg.norm(np.cross(sx, sy), axis=-1)
    lit = np.isfinite(value)
    if D is not None:
        lit &= np.hypot(x, y) <= 0.5 * D
    return np.where(lit, value, 0.0)


def cell_mean_intensity(grid: SphereGrid, F: float, D: float | None,
                        delta: Deformation | None = None, order: int = 3):
    """Cell means (power through the cell over its area) on ``grid``, shape (n_theta, n_phi).

    Gauss-Legendre quadrature of ``order`` points per direction with the sin(theta) area
    weight. In the row the rim image cuts, the theta range of each phi node ends where the
    preimage reaches r = D/2 (found by secant steps), so part-lit cells are exact too.
    """
    g, w = np.polynomial.legendre.leggauss(order)
    te, pe = grid.theta_edges, grid.phi_edges
    pc, pw = 0.5 * (pe[:-1] + pe[1:]), 0.5 * (pe[1:] - pe[:-1])
    p = (pc[:, None] + pw[:, None] * g[None, :]).ravel()            # (n_phi * order,)
    lo = np.repeat(te[:-1, None], p.size, axis=1)                   # (n_theta, n_phi * order)
    hi = np.repeat(te[1:, None], p.size, axis=1)
    if D is not None:
        t_rim = 2.0 * np.arctan(D / (4.0 * F))
        hi = np.minimum(hi, np.maximum(lo, _rim_image(p, F, grid.radius, D, delta, t_rim)))
    half = 0.5 * (hi - lo)
    T = 0.5 * (lo + hi)[..., None] + half[..., None] * g             # (n_theta, n_phi*order, q)
    P = np.broadcast_to(p[None, :, None], T.shape)
    values = np.zeros(T.shape)
    lit = half > 0
    values[lit] = intensity_at(T[lit], P[lit], F, grid.radius, delta, D)
    power = np.sum(values * np.sin(T) * w * half[..., None], axis=-1)   # per phi node
    power = np.sum(power.reshape(grid.n_theta, grid.n_phi, order) * w * pw[None, :, None], axis=-1)
    area = (np.cos(te[:-1]) - np.cos(te[1:]))[:, None] * (2.0 * pw)[None, :]
    return power / area


def _rim_image(phi, F, R, D, delta, t_rim, steps: int = 8):
    """theta (rad) at which the preimage of sphere direction (theta, phi) reaches r = D/2."""
    def excess(t):
        x, y = preimage(t, phi, F, R, delta)
        return np.hypot(x, y) - 0.5 * D

    t0, t1 = np.full(phi.shape, t_rim - 1e-3), np.full(phi.shape, t_rim + 1e-3)
    f0, f1 = excess(t0), excess(t1)
    for _ in range(steps):
        with np.errstate(divide="ignore", invalid="ignore"):  # a converged point: t1 == t0
            slope = np.where(f1 != f0, (f1 - f0) / (t1 - t0), np.inf)
        t2 = t1 - f1 / slope
        t0, f0 = t1, f1
        t1, f1 = t2, excess(t2)
        if np.all(np.abs(f1) < 1e-10):
            break
    return t1


def go_fieldmap(grid: SphereGrid, F: float, D: float, delta: Deformation | None,
                frequency_hz: float = 0.3e9, order: int = 3, ideal=None):
    """A GO FieldMap (cell means) of the reflector deformed by ``delta``, from this reference.

    ``ideal`` may pass a precomputed ideal cell-mean array to save its computation.
    """
    if ideal is None:
        ideal = cell_mean_intensity(grid, F, D, None, order)
    deformed = cell_mean_intensity(grid, F, D, delta, order)
    return fieldmap(grid, deformed, ideal, focal_length=F, diameter=D,
                    frequency_hz=frequency_hz, method="go", sampling="cell_mean",
                    attrs={"source": "tests/reference_go.py"})


def paper_delta(x, y, F: float = 33.0, D: float = 110.0, scale: float = 1.0):
    """The paper's deformation, Eq. 8 of PAPER.tex (docs/physics.md), in metres along z."""
    r = np.hypot(x, y)
    bump = np.sin((F / D) * np.sqrt(x * x + y * y + 0.5 * F)) / (50.0 * F)
    return scale * bump / (1.0 + np.exp(-0.6 * (0.4 * D - r)))


class GridSpline:
    """Bicubic spline through a finite gridded deformation x (nx,), y (ny,), dz (ny, nx) in m."""

    def __init__(self, x, y, dz):
        from scipy.interpolate import RectBivariateSpline

        self._spline = RectBivariateSpline(y, x, dz, kx=3, ky=3, s=0)

    def __call__(self, x, y):
        return self._spline.ev(y, x)

    def gradient(self, x, y):
        return self._spline.ev(y, x, dy=1), self._spline.ev(y, x, dx=1)


def reference_forward(order: int = 3):
    """A forward model for ``solver.nonlinear.refine`` built on this reference trace."""

    def forward(sphere, F, D, x, y, delta):
        surface = None if delta is None else GridSpline(x, y, delta)
        return cell_mean_intensity(sphere, F, D, surface, order)

    return forward
