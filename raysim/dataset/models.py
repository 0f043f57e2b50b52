"""Random surface-error models of a dataset: each draws one deformation with a target RMS.

A model draws the *shape* of its error from the sample's random generator (Zernike
coefficients, bump positions, panel pistons and tilts, the exponent of a rim astigmatism),
then scales the shape's linear parameters so that its RMS over the aperture grid
(:class:`raysim.maps.aperture.ApertureGrid`, re-exported here: the points r < D/2 of the map
the dataset stores, with the scene's panel layout) equals an RMS drawn from the spec's law. All lengths
are metres in the reflector frame of docs/physics.md (aperture coordinates x, y; delta along +z),
angles radians. Every model returns its parameters as a flat dict of numbers and arrays of
fixed length, so that the Zarr store holds them per sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from raysim.dataset.distributions import Distribution
from raysim.dataset.zernike import ZernikeSeries
from raysim.maps.aperture import ApertureGrid
from raysim.surface.deformation import Deformation, GaussianBumps, PanelRigid
from raysim.surface.panels import PanelLayout

Params = dict[str, Any]


@dataclass(frozen=True)
class Variable:
    """One per-sample parameter array of a model: extra dims after ``sample``, unit, meaning."""

    dims: tuple[str, ...]
    shape: tuple[int, ...]
    units: str
    long_name: str


@dataclass(frozen=True)
class ErrorModel:
    """Base of the models: ``name`` (prefix of its store variables), the law of its RMS (m)
    and the probability that a sample has this error at all."""

    name: str
    rms: Distribution
    probability: float

    kind: ClassVar[str] = ""
    linear: ClassVar[tuple[str, ...]] = ()  # parameters proportional to the amplitude

    def shape(self, rng: np.random.Generator, grid: ApertureGrid) -> Params:
        """Unscaled parameters of one draw."""
        raise NotImplementedError

    def build(self, params: Params, grid: ApertureGrid) -> Deformation:
        """The deformation the parameters describe."""
        raise NotImplementedError

    def variables(self, grid: ApertureGrid) -> dict[str, Variable]:
        """The parameters' per-sample layout, keyed like the dict :meth:`shape` returns."""
        raise NotImplementedError

    def draw(self, rng: np.random.Generator, grid: ApertureGrid) -> tuple[Deformation | None, Params]:
        """One sample of this error: (deformation or None when absent, parameters).

        Parameters carry ``present`` (0 or 1) and ``rms`` (m, the RMS drawn and reached on
        the grid; 0 when absent); the model's own parameters are NaN when absent.
        """
        if rng.random() >= self.probability:
            absent = {k: np.full(v.shape, np.nan) if v.shape else math.nan
                      for k, v in self.variables(grid).items()}
            return None, {"present": 0, "rms": 0.0, **absent}
        target = float(self.rms.draw(rng))
        params = self.shape(rng, grid)
        current = grid.rms(self.build(params, grid))
        factor = target / current if current > 0 else 0.0
        for key in self.linear:
            params[key] = params[key] * factor
        return self.build(params, grid), {"present": 1, "rms": target, **params}


@dataclass(frozen=True)
class ZernikeSpectrum(ErrorModel):
    """Zernike terms of radial orders n_min..n_max over the disk r <= D/2; each coefficient is
    Gaussian with a standard deviation falling as n^-decay before the whole is scaled."""

    n_min: int = 2
    n_max: int = 6
    decay: float = 1.0

    kind: ClassVar[str] = "zernike"
    linear: ClassVar[tuple[str, ...]] = ("coefficient",)

    @property
    def terms(self) -> list[tuple[int, int]]:
        """(n, m) of every term, m from -n to n in steps of 2 (m < 0: sin, m >= 0: cos)."""
        return [(n, m) for n in range(self.n_min, self.n_max + 1) for m in range(-n, n + 1, 2)]

    def shape(self, rng, grid):
        sd = np.array([max(n, 1) ** -self.decay for n, _ in self.terms])
        return {"coefficient": rng.standard_normal(len(sd)) * sd}

    def build(self, params, grid):
        rows = tuple((n, m, float(c)) for (n, m), c in zip(self.terms, params["coefficient"], strict=True))
        return ZernikeSeries(rows, 0.5 * grid.D)

    def variables(self, grid):
        return {"coefficient": Variable((f"{self.name}_term",), (len(self.terms),), "m",
                                        "Zernike coefficient over the disk r <= D/2: the term's RMS "
                                        "(Noll's normalisation; m < 0 sin, m >= 0 cos)")}


@dataclass(frozen=True)
class RandomBumps(ErrorModel):
    """``count`` Gaussian bumps (actuator scale ``sigma``, m) at points uniform over the disk
    r <= fraction * D/2, with Gaussian amplitudes scaled together."""

    count: Distribution
    sigma: Distribution  # m
    fraction: float = 1.0

    kind: ClassVar[str] = "bumps"
    linear: ClassVar[tuple[str, ...]] = ("amplitude",)

    @property
    def max_count(self) -> int:
        return int(self.count.support[1])

    def shape(self, rng, grid):
        k = int(self.count.draw(rng))
        pad = np.full(self.max_count, np.nan)
        r = 0.5 * grid.D * self.fraction * np.sqrt(rng.random(k))
        phi = 2.0 * np.pi * rng.random(k)
        out = {key: pad.copy() for key in ("x", "y", "amplitude", "sigma")}
        out["x"][:k] = r * np.cos(phi)
        out["y"][:k] = r * np.sin(phi)
        out["amplitude"][:k] = rng.standard_normal(k)
        out["sigma"][:k] = self.sigma.draw(rng, k)
        return out

    def build(self, params, grid):
        rows = np.column_stack([params["x"], params["y"], params["amplitude"], params["sigma"]])
        rows = rows[np.isfinite(rows).all(axis=1)]
        return GaussianBumps(tuple(tuple(float(v) for v in row) for row in rows))

    def variables(self, grid):
        dims, shape = (f"{self.name}_bump",), (self.max_count,)
        return {"x": Variable(dims, shape, "m", "bump centre x (NaN: no bump)"),
                "y": Variable(dims, shape, "m", "bump centre y (NaN: no bump)"),
                "amplitude": Variable(dims, shape, "m", "bump height at its centre"),
                "sigma": Variable(dims, shape, "m", "bump standard deviation (width)")}


@dataclass(frozen=True)
class PanelErrors(ErrorModel):
    """Rigid piston and tilts of every panel of the scene's layout (independent Gaussians,
    tilts with standard deviation sqrt(12) / sqrt(panel area) so each carries about the
    piston's share of the variance), scaled together."""

    kind: ClassVar[str] = "panel_rigid"
    linear: ClassVar[tuple[str, ...]] = ("piston", "tilt_x", "tilt_y")

    def shape(self, rng, grid):
        layout = _layout(grid)
        size = _panel_sizes(layout)
        n = layout.n_panels
        return {"piston": rng.standard_normal(n),
                "tilt_x": rng.standard_normal(n) * math.sqrt(12.0) / size,
                "tilt_y": rng.standard_normal(n) * math.sqrt(12.0) / size}

    def build(self, params, grid):
        return PanelRigid(_layout(grid), np.asarray(params["piston"], dtype=np.float64),
                          np.asarray(params["tilt_x"], dtype=np.float64),
                          np.asarray(params["tilt_y"], dtype=np.float64))

    def variables(self, grid):
        shape = (_layout(grid).n_panels,)
        return {"piston": Variable(("panel",), shape, "m", "panel piston at its centroid"),
                "tilt_x": Variable(("panel",), shape, "rad", "panel slope d delta / dx"),
                "tilt_y": Variable(("panel",), shape, "rad", "panel slope d delta / dy")}


@dataclass(frozen=True)
class RimAstigmatism(Deformation):
    """Gravity-like astigmatism growing to the rim: delta = A (r/a)^p cos(2 (phi - phi0)).

    ``amplitude`` A (m) is the peak value on the rim r = a (``radius``, m); ``exponent`` p >= 2
    (p = 2 is the harmonic Zernike astigmatism, which the intensity hardly sees; p > 2 bends
    the surface more towards the rim); ``angle`` phi0 (rad) is the axis of cos 2(phi - phi0),
    the high side where A > 0 (A takes either sign, so half the samples are low there).
    Its RMS over the disk r <= a is |A| / sqrt(2 (p + 1)).
    """

    amplitude: float
    exponent: float
    angle: float
    radius: float

    def geometry(self, x, y) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        """(phi, rho = r / a, cos phi, sin phi) at (x, y): what a value there owes to the
        points and the radius alone, so a caller may keep it for fixed points."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        r = np.hypot(x, y)
        phi = np.arctan2(y, x)
        return phi, r / self.radius, np.cos(phi), np.sin(phi)

    def evaluate(self, x, y, gradient: bool, geometry=None):
        """(delta, d/dx, d/dy) at (x, y) (the gradient None unless asked), from ``geometry``
        (as :meth:`geometry` gives it at these points) when given."""
        phi, rho, c, s = self.geometry(x, y) if geometry is None else geometry
        c2 = np.cos(2.0 * (phi - self.angle))
        value = self.amplitude * rho**self.exponent * c2
        if not gradient:
            return value, None, None
        s2 = np.sin(2.0 * (phi - self.angle))
        base = self.amplitude * rho ** (self.exponent - 1.0) / self.radius  # A rho^(p-1) / a
        d_dr = self.exponent * base * c2
        d_tangential = -2.0 * base * s2  # (1/r) d/dphi
        return value, c * d_dr - s * d_tangential, s * d_dr + c * d_tangential

    def __call__(self, x, y, panel=None):
        return self.evaluate(x, y, gradient=False)[0]

    def gradient(self, x, y, panel=None):
        _, gx, gy = self.evaluate(x, y, gradient=True)
        return gx, gy

    def describe(self) -> str:
        return (f"rim astigmatism {self.amplitude * 1e6:g} um (r/a)^{self.exponent:g} "
                f"at {math.degrees(self.angle):g} deg")


@dataclass(frozen=True)
class GravityAstigmatism(ErrorModel):
    """:class:`RimAstigmatism` with exponent and axis angle drawn from their laws, a random
    sign, and the amplitude scaled to the RMS drawn."""

    exponent: Distribution
    angle: Distribution  # rad

    kind: ClassVar[str] = "gravity"
    linear: ClassVar[tuple[str, ...]] = ("amplitude",)

    def shape(self, rng, grid):
        sign = 1.0 if rng.random() < 0.5 else -1.0
        return {"amplitude": sign, "exponent": float(self.exponent.draw(rng)),
                "angle": float(self.angle.draw(rng))}

    def build(self, params, grid):
        return RimAstigmatism(float(params["amplitude"]), float(params["exponent"]),
                              float(params["angle"]), 0.5 * grid.D)

    def variables(self, grid):
        return {"amplitude": Variable((), (), "m", "rim astigmatism: value on the rim at phi0"),
                "exponent": Variable((), (), "1", "rim astigmatism: power p of r/a"),
                "angle": Variable((), (), "rad", "rim astigmatism: axis phi0 of cos 2(phi - phi0), the high "
                                  "side where the amplitude is positive")}


@lru_cache(maxsize=8)
def _panel_sizes(layout: PanelLayout) -> NDArray[np.float64]:
    """Square root of each panel's area (m)."""
    return np.sqrt([max(layout.panel_area(p), 1e-12) for p in range(layout.n_panels)])


def _layout(grid: ApertureGrid) -> PanelLayout:
    if grid.layout is None:  # the spec loader refuses this; a guard for direct API use
        raise ValueError("panel errors need a scene with a [panels] layout")
    return grid.layout


MODELS: dict[str, type[ErrorModel]] = {
    m.kind: m for m in (ZernikeSpectrum, RandomBumps, PanelErrors, GravityAstigmatism)
}
