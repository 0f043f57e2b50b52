"""Independent geometric-optics reference for tests: exact GO intensity on the probe sphere.

Frame (DESIGN.md): vertex at the origin, axis +z, focus C = (0, 0, F); lengths in metres,
angles in radians. The reflector is the smooth surface z = r^2 / (4F) + delta(x, y), lit by a
plane wave travelling along -z with unit intensity. The probe sphere has radius R around C.

This module shares no code with ``raysim.go`` or ``solver``: it inverts the ray map point by
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

from raysim.field import fieldmap
from raysim.sphere import SphereGrid

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
    weight. Accurate to about 1e-12 for cells wholly inside the rim image; cells the rim image
    cuts are approximate (the cut is not resolved).
    """
    g, w = np.polynomial.legendre.leggauss(order)
    te, pe = grid.theta_edges, grid.phi_edges
    tc, tw = 0.5 * (te[:-1] + te[1:]), 0.5 * (te[1:] - te[:-1])
    pc, pw = 0.5 * (pe[:-1] + pe[1:]), 0.5 * (pe[1:] - pe[:-1])
    t = tc[:, None] + tw[:, None] * g[None, :]                    # (n_theta, order)
    p = pc[:, None] + pw[:, None] * g[None, :]                    # (n_phi, order)
    T = t[:, None, :, None]
    P = p[None, :, None, :]
    T, P = np.broadcast_arrays(T, P)
    values = intensity_at(T, P, F, grid.radius, delta, D)
    weight = (w[:, None] * np.sin(t)[:, :, None])[:, None, :, :] * w[None, None, None, :]
    power = np.sum(values * weight, axis=(2, 3))
    return power / np.sum(weight, axis=(2, 3))


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
    """The paper's deformation, Eq. 8 of PAPER.tex (DESIGN.md), in metres along z."""
    r = np.hypot(x, y)
    bump = np.sin((F / D) * np.sqrt(x * x + y * y + 0.5 * F)) / (50.0 * F)
    return scale * bump / (1.0 + np.exp(-0.6 * (0.4 * D - r)))
