"""The linear inversion: FA on the sphere -> delta on the aperture, with one rim treatment.

Frame and units (docs/physics.md): sphere angles in rad, aperture x, y and delta in m, FA
dimensionless, G in m. The steps of the paper's method (Eqs. 28-34): FA is resampled onto the
aperture grid through the ideal GO mapping r = 2F tan(theta/2) (:mod:`solver.resample`),
divided by G = -2 F d / R (:mod:`solver.equation`), and the Poisson equation
Laplacian(delta) = FA / G is solved on the disk (:mod:`solver.poisson`) with rim values zero
(the paper) or fitted to rim targets by a harmonic correction (:mod:`solver.boundary`).

:class:`Scan` is what an inversion reads from a FieldMap (its attributes alone, no scene);
:class:`LinearInverse` holds the settings of the linear map and applies it. Nothing in either
changes after construction: every method returns its result.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from raysim.maps.fieldmap import grid_of
from raysim.maps.fieldmap import validate as validate_fieldmap
from raysim.maps.sphere import SphereGrid
from raysim.surface.obstacles import ObstacleMesh
from solver import boundary
from solver.aperture import ApertureGrid
from solver.equation import G
from solver.errors import SolverError
from solver.nonlinear import extend_outside
from solver.poisson import SolveInfo, solve_poisson
from solver.resample import Coverage, fill_along_phi, sphere_to_aperture, usable_rows

MAX_INCIDENCE = 1e-3  # rad: the equation and the GO model assume an on-axis plane wave


@dataclass(frozen=True)
class Scan:
    """What the inversion reads from a FieldMap (attributes alone, no scene needed).

    ``blocked`` (n_theta, n_phi) bool: the cells obstacles hide (the FieldMap's ``blocked``;
    None without), whose samples the scan then holds as missing (NaN); ``obstacles``: their
    triangles (an ObstacleMesh), which the forward models put in the beam.
    """

    sphere: SphereGrid
    F: float
    D: float
    R: float
    intensity: NDArray[np.float64]
    intensity_ideal: NDArray[np.float64]
    intensity_std: NDArray[np.float64] | None
    attrs: dict
    blocked: NDArray[np.bool_] | None = None
    obstacles: ObstacleMesh | None = None

    @classmethod
    def from_fieldmap(cls, ds: xr.Dataset) -> Scan:
        ds = validate_fieldmap(ds)
        tilt = float(ds.attrs.get("incidence_theta", 0.0))
        if abs(tilt) > MAX_INCIDENCE:
            raise SolverError(f"the inversion assumes an on-axis plane wave; this scan's source "
                              f"is {np.degrees(tilt):.3f} deg off axis")
        std = ds["intensity_std"].values if "intensity_std" in ds.data_vars else None
        intensity = ds["intensity"].values.astype(np.float64)
        blocked = ds["blocked"].values.astype(bool) if "blocked" in ds.data_vars else None
        if blocked is not None:
            # hidden cells are missing samples: filled like any other hole (solver.resample)
            intensity = np.where(blocked, np.nan, intensity)
        return cls(grid_of(ds), float(ds.attrs["focal_length"]), float(ds.attrs["diameter"]),
                   float(ds.attrs["sphere_radius"]), intensity,
                   ds["intensity_ideal"].values.astype(np.float64),
                   None if std is None else std.astype(np.float64), dict(ds.attrs),
                   blocked, obstacles_of(ds))

    def first_rows(self, n: int) -> Scan:
        """The scan cut to its first ``n`` theta rows (the sphere grid ends at their outer edge)."""
        sphere = replace(self.sphere, n_theta=n, theta_max=float(self.sphere.theta_edges[n]))

        def cut(a):
            return None if a is None else a[:n]

        return replace(self, sphere=sphere, intensity=self.intensity[:n],
                       intensity_ideal=self.intensity_ideal[:n],
                       intensity_std=cut(self.intensity_std), blocked=cut(self.blocked))


def obstacles_of(ds: xr.Dataset) -> ObstacleMesh | None:
    """The obstacles' triangles a FieldMap carries (``obstacle_vertices`` in m, reflector frame,
    and ``obstacle_faces``), or None."""
    if "obstacle_vertices" not in ds.data_vars or "obstacle_faces" not in ds.data_vars:
        return None
    vertices = np.asarray(ds["obstacle_vertices"].values, dtype=np.float64)
    faces = np.asarray(ds["obstacle_faces"].values, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3 \
            or not np.all(np.isfinite(vertices)) or (faces.size and (faces.min() < 0 or
                                                                     faces.max() >= len(vertices))):
        raise SolverError("the FieldMap's obstacle_vertices / obstacle_faces are not a triangle "
                          "mesh ((n, 3) finite metres, (m, 3) indices into them)")
    return ObstacleMesh(vertices, faces, str(ds.attrs.get("obstacles", "")))


@dataclass(frozen=True)
class LinearSolution:
    """The linear answer to one FA map: delta (m, (N, N)), the Poisson solve's report and what
    the sphere data covered."""

    delta: NDArray[np.float64]
    info: SolveInfo
    coverage: Coverage


@dataclass(frozen=True, eq=False)
class LinearInverse:
    """The linear map FA on the sphere -> delta on the aperture, with one rim treatment.

    ``solver``, ``iterations``, ``omega``, ``tol``: the Poisson solve (:func:`solve_poisson`);
    ``targets`` (None: zero rim) and ``max_harmonics``: the rim fit; ``weight`` (n_theta,
    n_phi, or None for 1): a per-cell factor applied to FA on the sphere before resampling.
    """

    scan: Scan
    grid: ApertureGrid
    solver: str
    iterations: int | None = None
    omega: float | None = None
    tol: float = 1e-10
    targets: boundary.RimTargets | None = None
    max_harmonics: int = boundary.MAX_HARMONICS
    weight: NDArray[np.float64] | None = None

    @cached_property
    def G(self) -> NDArray[np.float64]:
        """G = -2 F d / R (m) at every aperture point."""
        return G(self.grid.r, self.scan.F, self.scan.R)

    def solve_poisson(self, fa_aperture: NDArray[np.float64], g=None
                      ) -> tuple[NDArray[np.float64], SolveInfo]:
        """delta (m) with Laplacian(delta) = FA / G inside the disk and rim values ``g``."""
        rhs = np.where(self.grid.mask, fa_aperture / self.G, 0.0)
        return solve_poisson(self.grid, rhs, g, self.solver, iterations=self.iterations,
                             omega=self.omega, tol=self.tol)

    def poisson(self, fa_aperture: NDArray[np.float64], g=None) -> NDArray[np.float64]:
        """:meth:`solve_poisson`'s delta alone (m)."""
        return self.solve_poisson(fa_aperture, g)[0]

    def resample(self, fa_sphere: NDArray[np.float64]) -> tuple[NDArray[np.float64], Coverage]:
        """FA on the sphere -> on the aperture grid (ideal GO mapping), and the data's coverage.

        Blocked cells (``scan.blocked``) are filled along phi first (:func:`fill_along_phi`:
        a leg's shadow is narrow in phi, long in theta); wholly blocked rows and other missing
        samples by the inpainting of :func:`solver.resample.fill_missing`."""
        scan = self.scan
        if scan.blocked is not None:
            fa_sphere, _ = fill_along_phi(fa_sphere, scan.blocked,
                                          usable_rows(scan.sphere, scan.F, scan.D))
        return sphere_to_aperture(fa_sphere, scan.sphere, self.grid, scan.F, scan.D)

    def to_aperture(self, fa_sphere: NDArray[np.float64]) -> NDArray[np.float64]:
        """:meth:`resample`'s values alone."""
        return self.resample(fa_sphere)[0]

    def rim_update(self, delta: NDArray[np.float64]) -> NDArray[np.float64]:
        """Harmonic correction (m) that moves ``delta`` onto the rim targets (zero without)."""
        if self.targets is None:
            return np.zeros_like(delta)
        from scipy.interpolate import RegularGridInterpolator  # slow to import; rims only

        filled = extend_outside(self.grid, delta)
        at = RegularGridInterpolator((self.grid.y, self.grid.x), filled, bounds_error=False,
                                     fill_value=None)
        misfit = self.targets.dz - at(np.stack([self.targets.y, self.targets.x], axis=-1))
        series = boundary.fit_harmonic(self.targets, misfit, self.grid.a, self.max_harmonics)
        return self.poisson(np.zeros_like(delta), series)

    def solve(self, fa_sphere: NDArray[np.float64]) -> LinearSolution:
        """delta (m) for FA on the sphere (times ``weight``), rim values zero or fitted."""
        if self.weight is not None:
            fa_sphere = fa_sphere * self.weight
        fa, coverage = self.resample(fa_sphere)
        delta, info = self.solve_poisson(fa)
        return LinearSolution(delta + self.rim_update(delta), info, coverage)

    def correct(self, misfit_sphere: NDArray[np.float64],
                delta: NDArray[np.float64]) -> NDArray[np.float64]:
        """Update (m) of ``delta`` for an FA misfit, keeping the rim on the targets."""
        update = self.poisson(self.to_aperture(misfit_sphere))
        return update + self.rim_update(delta + update)

    def describe_boundary(self) -> str:
        """The rim assumption in words, for the SurfaceMap."""
        if self.solver == "fft":
            return "zero on the enclosing square (fft); the rim of the disk is free"
        if self.targets is None:
            return "zero on the rim (the paper's assumption)"
        order = boundary.harmonic_order(self.targets, self.max_harmonics)
        return (f"rim targets: {len(self.targets)} points from {self.targets.source}, "
                f"harmonic fit of order {order}")
