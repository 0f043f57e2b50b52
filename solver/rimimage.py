"""Where a surface map puts the rim's image on the sphere, and the scan rows it leaves clean.

The ideal dish sends the ray from its rim to theta_rim = 2 atan(D / 4F) on the sphere (frame of
docs/physics.md: theta from -z at the focus). A deformed rim tilts that ray by twice the slope
of the deformation, so the rim's image moves in theta, differently at each azimuth. A scan row
whose outer edge lies within that movement of the ideal rim image is lit only in part where the
image moves inward: its power falls by the share of the cell left dark, which the
deformation-intensity equation (paper Eq. 20) reads as a curvature the surface does not have.
The linear solve takes that row, and the refinement cannot mend it (its model is compared only
on the rows :func:`solver.resample.modelled_rows` keeps), so one row biased by a few per cent
carried a Z(8, 4) of 60 um to 19 um of error (0.35 um without the row).

:func:`rim_image_shift` traces the rim's rays through a map with the reflection law in float64
(a plane wave along -z, the inversion's premise); :func:`rows_clear_of_rim` counts the rows whose
outer edge stays inside the image wherever it moves.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from raysim.maps.sphere import SphereGrid, theta_rim
from raysim.surface.gridded import GriddedMap
from solver.aperture import ApertureGrid
from solver.nonlinear import extend_outside
from solver.resample import MAX_GAP_CELLS

#: azimuths at which the rim's rays are traced (0.25 deg apart)
N_AZIMUTHS = 1440


def rim_ray_theta(F: float, D: float, R: float, phi: NDArray[np.float64],
                  dz: NDArray[np.float64], slope_x: NDArray[np.float64],
                  slope_y: NDArray[np.float64]) -> NDArray[np.float64]:
    """theta (rad) at which the ray that the rim point at azimuth ``phi`` (rad) reflects meets
    the sphere of radius ``R`` (m) about the focus, when the surface there is the paraboloid
    z = r^2 / 4F raised by ``dz`` (m, along z) with slopes ``slope_x``, ``slope_y`` of that
    deformation (dimensionless). A plane wave travels along -z; the sphere lies between the
    rim and the focus (R < F + D^2 / 16F), so the ray meets it on its way in.
    """
    a = 0.5 * D
    x, y = a * np.cos(phi), a * np.sin(phi)
    normal = np.stack([-(x / (2.0 * F) + slope_x), -(y / (2.0 * F) + slope_y), np.ones_like(x)])
    normal /= np.linalg.norm(normal, axis=0)
    # reflection of d = (0, 0, -1): d - 2 (d . n) n
    ray = 2.0 * normal[2] * normal
    ray[2] -= 1.0
    p = np.stack([x, y, a * a / (4.0 * F) + dz - F])  # from the focus
    b = np.sum(p * ray, axis=0)
    c = np.sum(p * p, axis=0) - R * R
    t = -b - np.sqrt(np.maximum(b * b - c, 0.0))
    hit = p + t * ray
    return np.arccos(np.clip(-hit[2] / R, -1.0, 1.0))


def rim_image_shift(grid: ApertureGrid, delta: NDArray[np.float64], F: float, D: float,
                    R: float) -> NDArray[np.float64]:
    """How far (rad, + outward) the map ``delta`` (m, NaN outside the disk) moves the rim's image
    in theta, at :data:`N_AZIMUTHS` azimuths.

    The map's height and slopes are read one grid step inside the rim, on its spline with the
    continuation the forward models use (beyond the outermost grid centres, on the axes, the
    spline holds their values and has no slope).
    """
    spline = GriddedMap(grid.x, grid.y, extend_outside(grid, delta))
    phi = np.linspace(0.0, 2.0 * np.pi, N_AZIMUTHS, endpoint=False)
    r = grid.a - grid.h
    x, y = r * np.cos(phi), r * np.sin(phi)
    slope_x, slope_y = spline.gradient(x, y)
    return rim_ray_theta(F, D, R, phi, spline(x, y), slope_x, slope_y) - theta_rim(D, F)


def rows_clear_of_rim(sphere: SphereGrid, F: float, D: float, n_rows: int,
                      shift: NDArray[np.float64]) -> int:
    """Of the ``n_rows`` usable rows, how many lead ones end inside the rim image wherever the
    ``shift`` (rad) moves it, in or out: the map is an estimate, and a row made dark in part
    pulls the map's image outward where the surface moves it in. Never fewer than four rows,
    nor so few that the last stops more than MAX_GAP_CELLS cells short of the rim image (the
    continuation beyond the data would then be too long).
    """
    reach = float(np.max(np.abs(shift))) if shift.size else 0.0
    edges_hi = sphere.theta_edges[1:n_rows + 1]
    clear = int(np.count_nonzero(edges_hi <= theta_rim(D, F) - reach))
    within = np.flatnonzero(theta_rim(D, F) - sphere.theta[:n_rows]
                            <= MAX_GAP_CELLS * sphere.dtheta)
    fewest = max(4, int(within[0]) + 1) if within.size else n_rows
    return min(n_rows, max(clear, fewest))
