"""Intensity between the cell centres of a FieldMap: bilinear, periodic in phi, through the pole.

A simulated probe (the simulated rig, a dataset's measurement effects) reads a FieldMap at its
true direction, which calibration errors move off the cell centres. Bilinear interpolation in
(theta, phi) returns the stored value at a cell centre exactly, is exact for functions
a + b theta + c phi + d theta phi inside a cell, never overshoots near the rim image, and
spreads a missing (NaN) sample only to its neighbours. In phi the grid wraps when it closes
around the axis. Below the first theta row, when the grid starts at theta = 0 and closes around
the axis with an even number of phi cells, the row mirrored through the pole (row 0 seen from
phi + pi) lies one step below; elsewhere beyond the grid the edge value holds.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray

from raysim.maps.fieldmap import grid_of
from raysim.maps.probe import ideal_weight, probe_of
from raysim.maps.sphere import SphereGrid, ideal_go_intensity


class FieldSampler:
    """Bilinear sampler of an (n_theta, n_phi) array on a :class:`SphereGrid`.

    Parameters
    ----------
    values : array (n_theta, n_phi), e.g. intensity relative to the incident wave.
    grid : the cell grid (angles in rad, radius in m).
    """

    def __init__(self, values: ArrayLike, grid: SphereGrid) -> None:
        self.values = np.asarray(values, dtype=np.float64)
        if self.values.shape != (grid.n_theta, grid.n_phi):
            raise ValueError(f"values {self.values.shape} do not match the grid "
                             f"({grid.n_theta}, {grid.n_phi})")
        self.grid = grid
        self.periodic = grid.full_circle
        self.mirror = (self.periodic and grid.n_phi % 2 == 0
                       and abs(grid.theta_min) < 1e-12)

    @classmethod
    def from_fieldmap(cls, ds: xr.Dataset, variable: str = "intensity") -> FieldSampler:
        """Sampler of one variable of a FieldMap (its grid from coordinates and attributes)."""
        return cls(ds[variable].values, grid_of(ds))

    @property
    def radius(self) -> float:
        """Radius of the sphere the values live on (m)."""
        return self.grid.radius

    def __call__(self, theta: ArrayLike, phi: ArrayLike) -> NDArray[np.float64]:
        """Values at directions (theta, phi) in rad (broadcast together)."""
        theta, phi = np.broadcast_arrays(np.asarray(theta, dtype=np.float64),
                                         np.asarray(phi, dtype=np.float64))
        g = self.grid
        # fractional row index: centres at integers 0 .. n_theta-1
        v = _snap((theta - g.theta_min) / g.dtheta - 0.5)
        lowest = -1.0 if self.mirror else 0.0
        v = np.clip(v, lowest, g.n_theta - 1)
        i0 = np.minimum(np.floor(v).astype(np.int64), g.n_theta - 2 if g.n_theta > 1 else 0)
        i0 = np.maximum(i0, -1 if self.mirror else 0)
        wt = v - i0
        lower = self._row(i0, phi)
        upper = self._row(np.minimum(i0 + 1, g.n_theta - 1), phi)
        return np.where(wt == 0.0, lower,
                        np.where(wt == 1.0, upper, (1.0 - wt) * lower + wt * upper))

    def _row(self, i: NDArray[np.int64], phi: NDArray[np.float64]) -> NDArray[np.float64]:
        """Row i (i = -1: the mirrored row 0) interpolated in phi."""
        g = self.grid
        phi = np.where(i < 0, phi + np.pi, phi)
        i = np.maximum(i, 0)
        u = _snap((phi - g.phi_min) / g.dphi - 0.5)
        if self.periodic:
            u = np.mod(u, g.n_phi)
            j0 = np.floor(u).astype(np.int64)
            w = u - j0
            j0 = np.mod(j0, g.n_phi)
            j1 = np.mod(j0 + 1, g.n_phi)
        else:
            u = np.clip(u, 0.0, g.n_phi - 1)
            j0 = np.minimum(np.floor(u).astype(np.int64), max(g.n_phi - 2, 0))
            w = u - j0
            j1 = np.minimum(j0 + 1, g.n_phi - 1)
        a = self.values[i, j0]
        b = self.values[i, j1]
        # an exact weight of 0 or 1 returns the stored value even beside a NaN neighbour
        return np.where(w == 0.0, a, np.where(w == 1.0, b, (1.0 - w) * a + w * b))


class SphereField:
    """Intensity anywhere near the probe sphere, from a FieldMap (what the simulated probe sees).

    The map's ratio intensity / intensity_ideal is interpolated (it is smooth where the
    intensity itself varies by a factor of three over the hemisphere, and it makes GO cell
    means and PO centre values alike) and multiplied by the ideal paraboloid's exact point
    value (rho / R)^2 at the probe's direction; beyond the rim image the ideal is 0. Off the
    sphere, at distance r from the focus, the intensity scales as (R / r)^2: the reflected
    rays converge on the focus. Cells beyond the rim image (ideal 0) take the ratio of the
    last lit cell below them, so that directions between the last lit centre and the rim
    image interpolate between finite values.

    A map measured with a probe other than the ideal meter (:mod:`raysim.maps.probe`) holds the
    probe's reading, which a cross-polar probe makes vanish in whole planes, so a ratio is not
    defined there: the difference intensity - intensity_ideal is interpolated instead and added
    to the probe's exact reading of the ideal paraboloid at the point
    (:func:`raysim.maps.probe.ideal_weight` times (rho / R)^2). Either way the simulation's own
    discretisation error, common to both intensities, cancels: at the 1e-5 level that moves an
    inverted map by tens of um (the constant-FA shape delta_c is 2.5 m at the centre per unit FA on
    the paper's dish, solver.gainmode).

    A map of a scene with obstacles (a ``blocked_share`` variable, :mod:`raysim.optics.blockage`)
    holds blocked intensities: the exact ideal is then blocked too, times (1 - the blocked
    share) interpolated, so a probe in a shadow reads the shadow (a wholly hidden cell reads 0).

    Parameters
    ----------
    ratio : sampler of intensity / intensity_ideal (NaN where the ideal is 0), or with
        ``weight`` of intensity - intensity_ideal.
    F, D : focal length and diameter of the reflector (m).
    weight : the probe's reading of the ideal paraboloid per unit intensity at (theta, phi),
        None for the ideal meter (the ratio form).
    blocked : sampler of the map's blocked share (0..1), None without obstacles.
    """

    def __init__(self, ratio: FieldSampler, F: float, D: float,
                 weight: Callable[[ArrayLike, ArrayLike], NDArray[np.float64]] | None = None,
                 blocked: FieldSampler | None = None) -> None:
        self.ratio = ratio
        self.F = F
        self.D = D
        self.weight = weight
        self.blocked = blocked

    @classmethod
    def from_fieldmap(cls, ds: xr.Dataset) -> SphereField:
        """From a FieldMap's intensities and attributes (F, D, R in m)."""
        ideal = ds["intensity_ideal"].values
        F, D = float(ds.attrs["focal_length"]), float(ds.attrs["diameter"])
        probe = probe_of(ds)
        blocked = None
        if "blocked_share" in ds.data_vars:
            blocked = FieldSampler(np.clip(ds["blocked_share"].values, 0.0, 1.0), grid_of(ds))
        if not probe.ideal:
            difference = np.where(ideal > 0, ds["intensity"].values - ideal, 0.0)
            polarization = float(ds.attrs.get("polarization", 0.0))
            return cls(FieldSampler(difference, grid_of(ds)), F, D,
                       lambda theta, phi: ideal_weight(probe, theta, phi, F, polarization),
                       blocked)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(ideal > 0, ds["intensity"].values / ideal, np.nan)
        for i in range(1, ratio.shape[0]):
            dark = ideal[i] <= 0
            ratio[i, dark] = ratio[i - 1, dark]
        return cls(FieldSampler(ratio, grid_of(ds)), F, D, None, blocked)

    @property
    def radius(self) -> float:
        """Radius R of the map's sphere (m)."""
        return self.ratio.radius

    def __call__(self, theta: float, phi: float, r: float) -> float:
        """Intensity relative to the incident wave at (theta, phi) in rad, r in m from the
        focus (0 where there is none: beyond the rim image, or no data)."""
        return float(self.values(theta, phi, r))

    def values(self, theta: ArrayLike, phi: ArrayLike, r: ArrayLike) -> NDArray[np.float64]:
        """:meth:`__call__` at many points at once (rad, rad, m; broadcast together)."""
        theta, phi, r = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (theta, phi, r)))
        ideal = ideal_go_intensity(theta, self.F, self.radius, self.D)
        lit = ideal > 0.0
        if self.blocked is not None:
            ideal = ideal * (1.0 - self.blocked(theta, phi))
        if self.weight is None:
            value = self.ratio(theta, phi) * ideal
        else:
            value = ideal * self.weight(theta, phi) + self.ratio(theta, phi)
        value = value * (self.radius / r) ** 2
        return np.where(lit & np.isfinite(value), value, 0.0)


def _snap(index: NDArray[np.float64]) -> NDArray[np.float64]:
    """Fractional indices within 1e-9 of an integer (a cell centre up to rounding) made exact."""
    nearest = np.round(index)
    return np.where(np.abs(index - nearest) < 1e-9, nearest, index)
