"""Example maps made without the ray engine or the solver, shared by the tests of the pictures
and the report: a FieldMap from the linear deformation-intensity equation and a SurfaceMap on
an aperture grid.

Frame (docs/physics.md): reflector vertex at the origin, axis +z, focus (0, 0, F); sphere angles in
rad; lengths and delta in m. The FieldMap's deformed intensity is I_ideal / (1 + FA) with
FA = G Laplacian(delta), G = -2 F d / R, d = F + z - R, at the aperture point r = 2F tan(theta/2)
of each cell centre: the paper's Eq. 28, not a ray trace.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import xarray as xr

from raysim.maps.aperture import ApertureGrid
from raysim.maps.fieldmap import fieldmap
from raysim.maps.sphere import SphereGrid, aperture_radius, ideal_go_cell_mean, theta_rim
from raysim.maps.surfacemap import surfacemap as contract_surfacemap
from raysim.render.figures import laplacian
from solver.equation import G

Delta = Callable[[np.ndarray, np.ndarray], np.ndarray]


def equation_fieldmap(delta: Delta, D: float = 110.0, F: float = 33.0, R: float = 10.0,
                      n_theta: int = 90, n_phi: int = 360, frequency_hz: float = 0.3e9,
                      scene_name: str = "equation example", scene: str | None = None,
                      attrs: dict | None = None) -> xr.Dataset:
    """A GO-like FieldMap for the deformation ``delta`` (m) from the linear equation (see above).

    Cells beyond the rim image get intensity 0 in both maps, like a GO trace. ``scene`` (TOML
    text) and ``attrs`` are recorded as a simulated FieldMap records them.
    """
    grid = SphereGrid(R, n_theta, n_phi)
    e = grid.theta_edges
    ideal_row = ideal_go_cell_mean(e[:-1], e[1:], F, R, D)
    ideal = np.repeat(ideal_row[:, None], n_phi, axis=1)
    t, p = np.meshgrid(grid.theta, grid.phi, indexing="ij")
    r = aperture_radius(t, F)
    x, y = r * np.cos(p), r * np.sin(p)
    fa = G(r, F, R) * laplacian(delta, x, y)
    lit = t < theta_rim(D, F)
    deformed = np.where(lit, ideal / (1.0 + np.where(lit, fa, 0.0)), 0.0)
    return fieldmap(grid, deformed, ideal, focal_length=F, diameter=D, frequency_hz=frequency_hz,
                    method="go", sampling="cell_mean", scene=scene,
                    attrs={"scene_name": scene_name, "incidence_theta": 0.0, "incidence_phi": 0.0,
                           **(attrs or {})})


def surfacemap(delta: np.ndarray | Delta, D: float = 110.0, N: int = 128,
               truth: np.ndarray | Delta | None = None, attrs: dict | None = None,
               F: float = 33.0, R: float = 10.0) -> xr.Dataset:
    """A SurfaceMap (the contract of :mod:`raysim.maps.surfacemap`) on the N x N aperture grid.

    ``delta`` and ``truth`` are (N, N) arrays indexed [y, x] or callables delta(x, y), in m;
    NaN is put outside the aperture r < D/2. ``error`` = deformation - truth with a truth,
    whose RMS and RRMS the attributes carry as an inversion's would.
    """
    grid = ApertureGrid(D, N)

    def values(v: np.ndarray | Delta) -> np.ndarray:
        return grid.masked(v(*grid.XY) if callable(v) else v)

    all_attrs = {"solver": "example", "boundary": "zero on the rim", "harmonic_part": "unobservable",
                 "removed_terms": "none", "focal_length": F, "diameter": D, "sphere_radius": R}
    t = None if truth is None else values(truth)
    if t is not None:
        err = values(delta) - t
        M = float(np.nanmax(t) - np.nanmin(t))
        all_attrs["rms_m"] = float(np.sqrt(np.nanmean(err * err)))
        all_attrs["rrms"] = all_attrs["rms_m"] / M if M > 0 else float("nan")
    all_attrs.update(attrs or {})
    return contract_surfacemap(grid, values(delta), all_attrs, truth=t)
