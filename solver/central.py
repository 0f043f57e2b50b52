"""The central mode: what a blocked centre of the aperture leaves unobservable.

Frame and units (docs/physics.md): aperture x, y and r in m, delta in m, a = D/2. A feed cabin
or subreflector hides the middle of the aperture: the scan's first theta rows are blocked
(``Scan.blocked``), so the data say nothing about FA = G Laplacian(delta) for r < r_h (the
radius those rows map to, r = 2F tan(theta/2)). Any delta whose Laplacian lives inside that
disk and which is zero on the rim then goes unseen; outside the disk its leading part is the
monopole c log(r / a), harmonic on the observed annulus and zero on the rim, which the
inpainted hole fixes only by chance (higher multipoles fall off as (r_h / r)^n and are left).

So, like piston, tilt and focus when they are removed, the inversion fits the mode over the
observed annulus r >= r_h by least squares and removes it, records its coefficient c (m) and
says the mode is unobservable; the truth gets the same removal before the RMS. The mode is
the Poisson solution of a uniform source on the hidden disk (total flux 2 pi), zero on the
rim: log(r / a) for r >= r_h, log(r_h / a) + (r^2 - r_h^2) / (2 r_h^2) inside (smooth across
r_h, finite at the centre).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from solver.aperture import ApertureGrid


def hole_radius(blocked: NDArray[np.bool_] | None, theta_edges: NDArray[np.float64],
                F: float) -> float | None:
    """The radius r_h (m) on the aperture of the blocked centre: the leading theta rows whose
    cells are all blocked, mapped by r = 2F tan(theta/2) from their outer edge; None when the
    first row is not wholly blocked (``blocked`` (n_theta, n_phi), ``theta_edges`` in rad)."""
    if blocked is None or not blocked.shape[0] or not blocked[0].all():
        return None
    rows = np.all(blocked, axis=1)
    n = int(np.argmin(rows)) if not rows.all() else len(rows)
    return float(2.0 * F * np.tan(0.5 * theta_edges[n]))


def central_mode(grid: ApertureGrid, r_h: float) -> NDArray[np.float64]:
    """The mode (dimensionless, NaN outside the aperture) on ``grid`` for a hidden disk of
    radius ``r_h`` (m): see the module docstring."""
    a, r = grid.a, grid.r
    inside = np.log(r_h / a) + (r * r - r_h * r_h) / (2.0 * r_h * r_h)
    with np.errstate(divide="ignore"):
        mode = np.where(r >= r_h, np.log(np.maximum(r, r_h) / a), inside)
    return grid.masked(mode)


def remove_central_mode(grid: ApertureGrid, delta: NDArray[np.float64],
                        r_h: float | None) -> tuple[NDArray[np.float64], float | None]:
    """``delta`` (m) minus its least-squares central mode over the annulus r >= ``r_h``, and the
    coefficient c (m); ``delta`` and None unchanged when there is no hidden centre."""
    if r_h is None:
        return delta, None
    mode = central_mode(grid, r_h)
    use = grid.mask & (grid.r >= r_h) & np.isfinite(delta)
    c = float(np.dot(mode[use], delta[use]) / np.dot(mode[use], mode[use]))
    return delta - c * mode, c


def central_attrs(r_h: float | None, c: float | None) -> dict:
    """The SurfaceMap attributes of the central mode (nothing without a hidden centre)."""
    if r_h is None or c is None:
        return {}
    return {"central_hole_radius_m": r_h, "removed_central_mode_m": c,
            "central_mode": "unobservable: the blocked centre r < central_hole_radius_m leaves "
                            "c log(r/a) on the annulus (smooth inside), zero on the rim; fitted "
                            "over r >= central_hole_radius_m and removed from the map (and from "
                            "the truth before the RMS)",
            "central_mode_observable": False}
