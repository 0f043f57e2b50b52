"""Surface errors delta(x, y) of the main reflector, in metres along +z, with their slopes.

Every deformation is a callable on aperture coordinates (x, y) in metres (reflector frame of
DESIGN.md: vertex at the origin, axis +z) and returns delta in metres; ``gradient`` returns
(d delta / dx, d delta / dy), dimensionless. Panel rigid errors depend on the panel a point
belongs to, so every call takes an optional ``panel`` array of panel ids (-1: in a gap); when
it is omitted, the panel is found from (x, y). Deformations add: ``a + b``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.errors import SceneError
from raysim.surface.panels import PanelLayout

Array = NDArray[np.float64]


class Deformation:
    """Base class: delta(x, y) (m) and its gradient; zero everywhere unless overridden."""

    def __call__(self, x: ArrayLike, y: ArrayLike, panel: ArrayLike | None = None) -> Array:
        return np.zeros(np.broadcast(np.asarray(x), np.asarray(y)).shape)

    def gradient(self, x: ArrayLike, y: ArrayLike, panel: ArrayLike | None = None) -> tuple[Array, Array]:
        zero = self(x, y, panel)
        return np.zeros_like(zero), np.zeros_like(zero)

    def __add__(self, other: Deformation) -> Deformation:
        parts: list[Deformation] = []
        for d in (self, other):
            parts.extend(d.parts if isinstance(d, Sum) else [d])
        return Sum(tuple(parts))

    def describe(self) -> str:
        return "none"


@dataclass(frozen=True)
class NoDeformation(Deformation):
    """The ideal paraboloid."""


@dataclass(frozen=True)
class Sum(Deformation):
    """Sum of deformations."""

    parts: tuple[Deformation, ...]

    def __call__(self, x, y, panel=None):
        out = np.zeros(np.broadcast(np.asarray(x), np.asarray(y)).shape)
        for part in self.parts:
            out = out + part(x, y, panel)
        return out

    def gradient(self, x, y, panel=None):
        gx = np.zeros(np.broadcast(np.asarray(x), np.asarray(y)).shape)
        gy = np.zeros_like(gx)
        for part in self.parts:
            px, py = part.gradient(x, y, panel)
            gx, gy = gx + px, gy + py
        return gx, gy

    def describe(self) -> str:
        return " + ".join(p.describe() for p in self.parts) or "none"


@dataclass(frozen=True)
class PaperDeformation(Deformation):
    """The paper's Eq. 8 (peak-to-peak 1.2 mm, RMS 327.65 um over the aperture at scale 1):

    delta = sin((F/D) sqrt(x^2 + y^2 + F/2)) / (50 F) * 1 / (1 + exp(-0.6 (0.4 D - r))),

    with D, F and r in metres as the paper writes it, times ``scale``.
    """

    D: float
    F: float
    scale: float = 1.0

    def _parts(self, r: Array) -> tuple[Array, Array, Array, Array]:
        k = self.F / self.D
        s = np.sqrt(r * r + 0.5 * self.F)
        a = np.sin(k * s) / (50.0 * self.F)
        da_dr = np.cos(k * s) * k * r / s / (50.0 * self.F)
        b = 1.0 / (1.0 + np.exp(-0.6 * (0.4 * self.D - r)))
        db_dr = -0.6 * b * (1.0 - b)
        return a, da_dr, b, db_dr

    def __call__(self, x, y, panel=None):
        a, _, b, _ = self._parts(np.hypot(x, y))
        return self.scale * a * b

    def gradient(self, x, y, panel=None):
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        r = np.hypot(x, y)
        a, da, b, db = self._parts(r)
        d_dr = self.scale * (da * b + a * db)
        with np.errstate(invalid="ignore", divide="ignore"):
            cx = np.where(r > 0, x / r, 0.0)
            cy = np.where(r > 0, y / r, 0.0)
        return d_dr * cx, d_dr * cy

    def radial_profile(self, r: ArrayLike) -> Array:
        """delta along a radius (m); Eq. 8 depends on r alone."""
        a, _, b, _ = self._parts(np.asarray(r, dtype=np.float64))
        return self.scale * a * b

    def describe(self) -> str:
        return f"paper Eq. 8 x {self.scale:g}"


def paper_peak_to_peak(D: float, F: float) -> float:
    """Peak-to-peak (m) of Eq. 8 at scale 1 over the aperture r <= D/2 (about 1.2 mm)."""
    profile = PaperDeformation(D, F).radial_profile(np.linspace(0.0, 0.5 * D, 200001))
    return float(profile.max() - profile.min())


def zernike_radial(n: int, m: int, rho: Array) -> tuple[Array, Array, Array]:
    """R_n^m(rho), its derivative, and R_n^m(rho)/rho (finite for m >= 1), for rho >= 0."""
    m = abs(m)
    value = np.zeros_like(rho)
    deriv = np.zeros_like(rho)
    over = np.zeros_like(rho)
    for s in range((n - m) // 2 + 1):
        c = ((-1) ** s * math.factorial(n - s)
             / (math.factorial(s) * math.factorial((n + m) // 2 - s) * math.factorial((n - m) // 2 - s)))
        p = n - 2 * s
        value += c * rho**p
        if p >= 1:
            deriv += c * p * rho ** (p - 1)
            over += c * rho ** (p - 1)
    return value, deriv, over


@dataclass(frozen=True)
class Zernike(Deformation):
    """Zernike terms over the disk of radius ``radius`` (m), Noll-normalised.

    ``terms`` holds (n, m, coefficient in metres); m >= 0 takes cos(m phi), m < 0 sin(|m| phi).
    Noll normalisation: each term's RMS over the disk equals its coefficient.
    """

    terms: tuple[tuple[int, int, float], ...]
    radius: float

    def __post_init__(self) -> None:
        for n, m, _ in self.terms:
            if n < 0 or abs(m) > n or (n - abs(m)) % 2:
                raise SceneError(f"Zernike (n={n}, m={m}) does not exist: need |m| <= n, n - |m| even")

    def _eval(self, x, y):
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        rho = np.hypot(x, y) / self.radius
        phi = np.arctan2(y, x)
        c, s = np.cos(phi), np.sin(phi)
        value = np.zeros_like(rho)
        gx = np.zeros_like(rho)
        gy = np.zeros_like(rho)
        for n, m, coef in self.terms:
            norm = math.sqrt(2.0 * (n + 1) / (2.0 if m == 0 else 1.0))  # Noll: sqrt(2(n+1)/(1+delta_m0))
            R, dR, R_over = zernike_radial(n, m, rho)
            am = abs(m)
            ang = np.cos(am * phi) if m >= 0 else np.sin(am * phi)
            dang = -am * np.sin(am * phi) if m >= 0 else am * np.cos(am * phi)
            value += coef * norm * R * ang
            # d/dx = cos(phi) d/dr - sin(phi)/r d/dphi, with d/dr = (1/radius) d/drho
            gx += coef * norm / self.radius * (dR * ang * c - R_over * dang * s)
            gy += coef * norm / self.radius * (dR * ang * s + R_over * dang * c)
        return value, gx, gy

    def __call__(self, x, y, panel=None):
        return self._eval(x, y)[0]

    def gradient(self, x, y, panel=None):
        _, gx, gy = self._eval(x, y)
        return gx, gy

    def describe(self) -> str:
        return "zernike " + ", ".join(f"Z({n},{m})={c * 1e6:g}um" for n, m, c in self.terms)


@dataclass(frozen=True)
class GaussianBumps(Deformation):
    """Gaussian bumps: rows of (x0 m, y0 m, amplitude m, sigma m)."""

    bumps: tuple[tuple[float, float, float, float], ...]

    def _eval(self, x, y):
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        value = np.zeros(np.broadcast(x, y).shape)
        gx = np.zeros_like(value)
        gy = np.zeros_like(value)
        for x0, y0, amp, sigma in self.bumps:
            dx, dy = x - x0, y - y0
            g = amp * np.exp(-(dx * dx + dy * dy) / (2.0 * sigma * sigma))
            value += g
            gx += -g * dx / (sigma * sigma)
            gy += -g * dy / (sigma * sigma)
        return value, gx, gy

    def __call__(self, x, y, panel=None):
        return self._eval(x, y)[0]

    def gradient(self, x, y, panel=None):
        _, gx, gy = self._eval(x, y)
        return gx, gy

    def describe(self) -> str:
        return f"{len(self.bumps)} gaussian bumps"


@dataclass(frozen=True, eq=False)
class PanelRigid(Deformation):
    """Per-panel rigid errors: delta = piston + tilt_x (x - xc) + tilt_y (y - yc) on each panel.

    ``piston`` in metres, ``tilt_x`` = d delta / dx and ``tilt_y`` = d delta / dy in radians,
    one entry per panel id of ``layout``; (xc, yc) is the panel's area centroid. Zero in gaps.
    """

    layout: PanelLayout
    piston: NDArray[np.float64]
    tilt_x: NDArray[np.float64]
    tilt_y: NDArray[np.float64]

    def _ids(self, x, y, panel):
        if panel is None:
            return self.layout.panel_at(x, y)
        shape = np.broadcast(np.asarray(x), np.asarray(y)).shape
        return np.broadcast_to(np.asarray(panel, dtype=np.int64), shape)

    def __call__(self, x, y, panel=None):
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        ids = self._ids(x, y, panel)
        ok = ids >= 0
        k = np.where(ok, ids, 0)
        centres = self.layout.centres()
        value = (self.piston[k] + self.tilt_x[k] * (x - centres[k, 0])
                 + self.tilt_y[k] * (y - centres[k, 1]))
        return np.where(ok, value, 0.0)

    def gradient(self, x, y, panel=None):
        ids = self._ids(x, y, panel)
        ok = ids >= 0
        k = np.where(ok, ids, 0)
        return np.where(ok, self.tilt_x[k], 0.0), np.where(ok, self.tilt_y[k], 0.0)

    @classmethod
    def random(cls, layout: PanelLayout, rms: float, seed: int) -> PanelRigid:
        """Random pistons and tilts, scaled so the surface RMS over the panels is ``rms`` (m).

        Piston and each tilt carry about equal shares of the variance (tilts drawn with
        standard deviation sqrt(12) / L, L the square root of the panel area).
        """
        rng = np.random.default_rng(seed)
        n = layout.n_panels
        size = np.sqrt(np.array([max(layout.panel_area(p), 1e-12) for p in range(n)]))
        piston = rng.standard_normal(n)
        tx = rng.standard_normal(n) * np.sqrt(12.0) / size
        ty = rng.standard_normal(n) * np.sqrt(12.0) / size
        unit = cls(layout, piston, tx, ty)
        current = unit.rms_over_panels()
        s = rms / current if current > 0 else 0.0
        return cls(layout, piston * s, tx * s, ty * s)

    def rms_over_panels(self, samples: int = 801) -> float:
        """Area-weighted RMS (m) over the panel footprints, by a regular grid of samples."""
        a = self.layout.rim_radius
        g = np.linspace(-a, a, samples)
        x, y = np.meshgrid(g, g)
        ids = self.layout.panel_at(x, y)
        on = ids >= 0
        return float(np.sqrt(np.mean(self(x[on], y[on], ids[on]) ** 2)))

    def describe(self) -> str:
        return f"panel rigid errors ({self.layout.n_panels} panels)"


@dataclass(frozen=True, eq=False)
class GriddedMap(Deformation):
    """A deformation given on a regular grid: x (nx,), y (ny,) in m, dz (ny, nx) in m.

    Interpolated with a bicubic spline (continuous slopes). NaN samples (outside the aperture,
    say) are first filled by a harmonic extension of the known values, so the surface stays
    smooth up to and beyond the rim.
    """

    x: NDArray[np.float64]
    y: NDArray[np.float64]
    dz: NDArray[np.float64]
    scale: float = 1.0

    def __post_init__(self) -> None:
        from scipy.interpolate import RectBivariateSpline

        x = np.asarray(self.x, dtype=np.float64)
        y = np.asarray(self.y, dtype=np.float64)
        dz = np.asarray(self.dz, dtype=np.float64)
        if dz.shape != (len(y), len(x)) or len(x) < 4 or len(y) < 4:
            raise SceneError(f"gridded deformation needs dz of shape (ny, nx) with nx, ny >= 4, "
                             f"got {dz.shape} for nx={len(x)}, ny={len(y)}")
        if np.any(np.diff(x) <= 0) or np.any(np.diff(y) <= 0):
            raise SceneError("gridded deformation: x and y must increase strictly")
        if not np.any(np.isfinite(dz)):
            raise SceneError("gridded deformation holds no finite value")
        filled = _harmonic_fill(dz)
        spline = RectBivariateSpline(y, x, filled * self.scale, kx=3, ky=3, s=0)
        object.__setattr__(self, "_spline", spline)

    def __call__(self, x, y, panel=None):
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        shape = np.broadcast(x, y).shape
        xb, yb = np.broadcast_to(x, shape).ravel(), np.broadcast_to(y, shape).ravel()
        return self._spline.ev(yb, xb).reshape(shape)

    def gradient(self, x, y, panel=None):
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        shape = np.broadcast(x, y).shape
        xb, yb = np.broadcast_to(x, shape).ravel(), np.broadcast_to(y, shape).ravel()
        gx = self._spline.ev(yb, xb, dy=1).reshape(shape)
        gy = self._spline.ev(yb, xb, dx=1).reshape(shape)
        return gx, gy

    def describe(self) -> str:
        return f"gridded map {len(self.y)} x {len(self.x)}"

    @classmethod
    def from_file(cls, path: str | Path, scale: float = 1.0) -> GriddedMap:
        """Read a map: NetCDF with coords x, y (m) and ``deformation`` (m), or CSV x,y,dz (m)
        (checked by :func:`raysim.surface.gridded.read_map`)."""
        from raysim.surface.gridded import read_map

        return read_map(path, scale)


def _harmonic_fill(values: Array) -> Array:
    """Fill NaNs with the harmonic function (5-point Laplace) taking the known values."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.linalg import spsolve

    missing = ~np.isfinite(values)
    if not missing.any():
        return values.copy()
    ny, nx = values.shape
    index = -np.ones(values.shape, dtype=np.int64)
    index[missing] = np.arange(missing.sum())
    rows, cols, vals = [], [], []
    rhs = np.zeros(missing.sum())
    iy, ix = np.nonzero(missing)
    diag = np.zeros(missing.sum())
    for dy, dx in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        jy, jx = iy + dy, ix + dx
        inside = (jy >= 0) & (jy < ny) & (jx >= 0) & (jx < nx)
        me = index[iy[inside], ix[inside]]
        diag[inside] += 1.0
        neighbour = index[jy[inside], jx[inside]]
        unknown = neighbour >= 0
        rows.append(me[unknown])
        cols.append(neighbour[unknown])
        vals.append(-np.ones(unknown.sum()))
        known_vals = values[jy[inside], jx[inside]]
        np.add.at(rhs, me[~unknown], known_vals[~unknown])
    n = missing.sum()
    rows.append(np.arange(n))
    cols.append(np.arange(n))
    vals.append(diag)
    A = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    filled = values.copy()
    filled[missing] = spsolve(A.tocsc(), rhs)
    return filled


def zernike_terms_um(terms: Sequence[tuple[int, int, float]]) -> tuple[tuple[int, int, float], ...]:
    """Convert (n, m, coefficient um) rows to (n, m, metres)."""
    return tuple((int(n), int(m), float(c) * 1e-6) for n, m, c in terms)
