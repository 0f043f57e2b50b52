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

from raysim.errors import FieldMapError
from raysim.maps.fieldmap import grid_of
from raysim.maps.fieldmap import validate as validate_fieldmap
from raysim.maps.sphere import SphereGrid, ideal_go_intensity, theta_rim
from raysim.surface.obstacles import ObstacleMesh
from solver import boundary
from solver.aperture import ApertureGrid
from solver.equation import G, intensity_ratio_fa
from solver.errors import SolverError
from solver.nonlinear import extend_outside
from solver.poisson import SolveInfo, solve_poisson
from solver.resample import (
    MAX_HOLE_SHARE,
    Coverage,
    Hole,
    cap_rows,
    fill_along_phi,
    largest_hole,
    sphere_to_aperture,
    usable_rows,
)

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
        if std is not None:
            # a spread of zero is no measured reading's: a placeholder, or a simulated rig
            # without noise; read as no spread stated (NaN), so the noise is estimated from the
            # scan there, not taken as none (all zero made the map's stated spread 0.00 um)
            std = np.where(np.asarray(std, dtype=np.float64) > 0, std, np.nan)
        intensity = ds["intensity"].values.astype(np.float64)
        blocked = ds["blocked"].values.astype(bool) if "blocked" in ds.data_vars else None
        ideal = ds["intensity_ideal"].values.astype(np.float64)
        sphere = grid_of(ds)
        dark = dark_centre(ideal, blocked, sphere)
        if dark:  # a dish with a central hole: its centre is hidden like a cabin's shadow
            blocked = np.zeros(ideal.shape, dtype=bool) if blocked is None else blocked.copy()
            blocked[:dark] = True
        if blocked is not None:
            # hidden cells are missing samples: filled like any other hole (solver.resample)
            intensity = np.where(blocked, np.nan, intensity)
        return cls(sphere, float(ds.attrs["focal_length"]), float(ds.attrs["diameter"]),
                   float(ds.attrs["sphere_radius"]), intensity, ideal,
                   None if std is None else std.astype(np.float64), dict(ds.attrs),
                   blocked, obstacles_of(ds))

    def check_coverage(self) -> Hole | None:
        """What the scan covers inside the rim image: returns its largest hole of missing
        readings (cells an obstacle hides are not missing: their handling is the obstacles'),
        None without one. Raises when the ideal reflector
        leaves most cells dark (a dish that does not surround its axis, an offset dish: the
        inversion's mapping needs the axis), and when the hole is over MAX_HOLE_SHARE of the
        cells: the fill would invent the surface there."""
        used = self.first_rows(usable_rows(self.sphere, self.F, self.D))
        hidden = (np.zeros(used.intensity.shape, dtype=bool) if used.blocked is None
                  else used.blocked)
        dark = ~(used.intensity_ideal > 0) & ~hidden
        if dark.mean() > 0.5:
            raise FieldMapError(
                f"the ideal reflector lights only {100 * (1 - dark.mean()):.0f} % of the cells "
                "inside the rim image: the inversion needs a dish around its axis that fills "
                "the rim image (an offset dish, or a mesh whose axis is elsewhere, is not "
                "supported)")
        self._check_rim_image()
        self._check_lit_where_ideal_is_dark()
        missing = ~np.isfinite(intensity_ratio_fa(used.intensity, used.intensity_ideal))
        grid = used.sphere
        cap = cap_rows(self.sphere)
        if cap:  # the polar cap a scan starting off the pole does not reach is filled like a
            # hole (resample.from_the_pole), so it counts as one, joined to the first row's:
            # a scan from 25 deg was filled there in silence (the map's sign wrong at a bump)
            grid = SphereGrid(grid.radius, grid.n_theta + cap, grid.n_phi,
                              max(grid.theta_min - cap * grid.dtheta, 0.0), grid.theta_max,
                              grid.phi_min, grid.phi_max)
            missing = np.vstack([np.ones((cap, grid.n_phi), dtype=bool), missing])
            hidden = np.vstack([np.zeros((cap, grid.n_phi), dtype=bool), hidden])
        hole = largest_hole(missing & ~hidden, grid)
        if hole is not None and hole.share > MAX_HOLE_SHARE:
            raise FieldMapError(f"the scan misses a whole region ({hole.describe()}): the "
                                "inversion would fill it with a smooth guess; measure it")
        return hole

    def _check_rim_image(self) -> None:
        """Raise when the ideal intensity ends far from the rim image the ``focal_length`` and
        ``diameter`` attributes put at 2 atan(D / 4F): a wrong F or D shifts the mapping and
        the rows used (F = 30 m on the paper's 33 m map: 22 % RRMS, D = 100 m cut its outer
        ring, without a word). The ideal's edge is the first row after the last whose lit
        share (:func:`lit_share`) reaches a quarter of the lit rows' median (a sharp
        edge's part-lit row, or edge diffraction's quarter power at the shadow boundary). The
        rim image must lie within two rows of it, plus the edge's own width beyond its one
        part-lit row (from the last row at 3/4 of the median to the first under a tenth: a
        faceted mesh's rim spills light a row further, a small dish diffracts over several).
        """
        share = lit_share(self.intensity_ideal, self.blocked, self.sphere)
        lit = np.flatnonzero(share > 0.5 * share.max(initial=0.0))
        if lit.size == 0:
            return
        ref = float(np.median(share[lit]))
        edges, step = self.sphere.theta_edges, self.sphere.dtheta
        # the first row after the last one at a quarter of that: a ring gap's dark row inside
        # the dish (GO leaves a whole row dark where the gap's image covers it) is no edge
        # (a 5 m dish with 30 mm gaps was refused as having the wrong F or D)
        last = int(np.flatnonzero(share >= 0.25 * ref)[-1])
        edge = last + 1 if last + 1 < share.size else None
        rim = theta_rim(self.D, self.F)
        if edge is None:  # lit to the scan's end: the rim image is not before its last rows
            if rim < edges[-1] - 2.0 * step:
                self._wrong_rim(f"is lit up to theta = {np.degrees(edges[-1]):.1f} deg", rim)
            return
        bright = next((i for i in range(edge - 1, int(lit[0]) - 1, -1) if share[i] >= 0.75 * ref),
                      int(lit[0]))
        dark = next((i for i in range(edge, share.size) if share[i] < 0.1 * ref), share.size - 1)
        width = max(0.0, float(edges[dark] - edges[bright + 1]) - step)
        if abs(rim - edges[edge]) > 2.0 * step + width + 1e-9:
            self._wrong_rim(f"ends at theta = {np.degrees(edges[edge]):.1f} deg", rim)

    def _check_lit_where_ideal_is_dark(self) -> None:
        """Raise when whole rows of the scan are lit where its ideal intensity is dark: the
        ideal is then another dish's (an F = 36 m ideal on the paper's 33 m scan, its rim
        image 5 deg nearer the pole, passed the rim check within its tolerance and made a map
        88 000 % off, the lit band read as a missing region). Each row's lit share
        (:func:`lit_share`) is taken against its typical level, the median of the rows above
        a tenth of the largest (PO's ripple on a small dish swings rows from 0.2 to 1 of the
        largest): a row dark in the ideal (under a tenth of its level) and lit in the scan
        (over half of its level) is no surface's doing: a deformation moves the rim's image
        by a fraction of a row, and edge diffraction lights the boundary at a quarter."""
        ideal = lit_share(self.intensity_ideal, self.blocked, self.sphere)
        scan = lit_share(np.where(np.isfinite(self.intensity), self.intensity, np.nan),
                         self.blocked, self.sphere)

        def level(share: NDArray[np.float64]) -> float:
            lit = share[share > 0.1 * share.max(initial=0.0)]
            return float(np.median(lit)) if lit.size else 0.0

        rows = np.flatnonzero((ideal < 0.1 * level(ideal)) & (scan > 0.5 * level(scan)))
        if rows.size and level(ideal) > 0:
            edges = np.degrees(self.sphere.theta_edges)
            raise FieldMapError(
                f"the scan is lit in {rows.size} rows ({edges[rows[0]]:.1f} to "
                f"{edges[rows[-1] + 1]:.1f} deg) where its ideal intensity is dark: the ideal is "
                "not this dish's (another focal length or diameter?); give the ideal of the dish "
                "the scan measured")

    def _wrong_rim(self, where: str, rim: float) -> None:
        raise FieldMapError(
            f"the ideal intensity {where}, but focal_length = {self.F:g} m and diameter = "
            f"{self.D:g} m put the rim image at {np.degrees(rim):.1f} deg: one of them is not "
            "the dish's")

    def first_rows(self, n: int) -> Scan:
        """The scan cut to its first ``n`` theta rows (the sphere grid ends at their outer edge)."""
        sphere = replace(self.sphere, n_theta=n, theta_max=float(self.sphere.theta_edges[n]))

        def cut(a):
            return None if a is None else a[:n]

        return replace(self, sphere=sphere, intensity=self.intensity[:n],
                       intensity_ideal=self.intensity_ideal[:n],
                       intensity_std=cut(self.intensity_std), blocked=cut(self.blocked))


def lit_share(ideal: NDArray[np.float64], blocked: NDArray[np.bool_] | None,
              sphere: SphereGrid) -> NDArray[np.float64]:
    """Each theta row's azimuthal mean of ``ideal`` (cells not ``blocked``, dark ones as 0)
    over the ideal paraboloid's GO law (rho / R)^2 at the row's centre, which alone grows 3
    times from the pole to a rim image at 80 deg: about constant where the dish lights the
    row, 0 where it does not, a share between at an edge."""
    seen = ideal if blocked is None else np.where(blocked, np.nan, ideal)
    with np.errstate(invalid="ignore"):
        mean = np.nanmean(np.where(seen > 0, seen, 0.0), axis=1)
    law = ideal_go_intensity(sphere.theta, 1.0, 1.0)  # the shape: 1 / cos^4(theta / 2)
    return np.nan_to_num(mean, nan=0.0) / law


def dark_centre(ideal: NDArray[np.float64], blocked: NDArray[np.bool_] | None,
                sphere: SphereGrid) -> int:
    """How many leading theta rows to hide when the ideal reflector leaves the centre dark (a
    dish with a central hole, a Cassegrain's): when the first row's lit share
    (:func:`lit_share`) is under a tenth of the lit rows' median, the rows up to the first
    over half of it, and that one, which the hole's edge may light in
    part (its image moves with the surface, as the rim's does: :mod:`solver.rimimage`). None
    (0) when the first row is lit, or when an obstacle already hides the dark rows (its
    ``blocked`` cells: the obstacles' own handling)."""
    share = lit_share(ideal, blocked, sphere)
    bright = share > 0.5 * share.max(initial=0.0)
    if not bright.any():
        return 0
    ref = float(np.median(share[bright]))
    if share[0] >= 0.1 * ref:  # a lit pole (PO's interference leaves 0.46 of the peak there)
        return 0
    first = int(np.argmax(share > 0.5 * ref))
    if blocked is not None and blocked[:first].all():
        return 0
    return first + 1


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
