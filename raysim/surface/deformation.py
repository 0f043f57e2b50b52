"""Surface errors delta(x, y) of the main reflector, in metres along +z, with their slopes.

Every deformation is a callable on aperture coordinates (x, y) in metres (reflector frame of
docs/physics.md: vertex at the origin, axis +z) and returns delta in metres; ``gradient`` returns
(d delta / dx, d delta / dy), dimensionless. Panel rigid errors depend on the panel a point
belongs to, so every call takes an optional ``panel`` array of panel ids (-1: in a gap); when
it is omitted, the panel is found from (x, y). Deformations add: ``a + b``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.errors import SceneError
from raysim.surface.panels import PanelLayout

#: one Zernike term's factors at fixed points: R(rho), angular factor, d/dx and d/dy brackets
ZernikeFactors = tuple[NDArray, NDArray, NDArray | None, NDArray | None]

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
class Scaled(Deformation):
    """``factor`` times ``deformation`` (a first-order probe of an engine's answer, say)."""

    deformation: Deformation
    factor: float

    def __call__(self, x, y, panel=None):
        return self.factor * self.deformation(x, y, panel)

    def gradient(self, x, y, panel=None):
        gx, gy = self.deformation.gradient(x, y, panel)
        return self.factor * gx, self.factor * gy

    def describe(self) -> str:
        return f"{self.factor:g} x ({self.deformation.describe()})"


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


#: highest radial order n a Zernike term may have. The radial polynomials are evaluated stably
#: to far beyond it (see :func:`zernike_radial`), but a term of order n has about n / 2 radial
#: zero crossings, mostly near the rim: at n = 100 they lie centimetres apart on a 100 m dish,
#: finer than the aperture grids (256 points over the diameter) or the probe grid of one scan
#: can resolve, so a higher order is a typing mistake rather than a surface.
MAX_ZERNIKE_ORDER = 100


@lru_cache(maxsize=512)
def radial_coefficients(n: int, m: int) -> tuple[tuple[int, float], ...]:
    """(power, coefficient) pairs of the Zernike radial polynomial R_n^|m|(rho), the explicit
    factorial sum. For reference only: summed in floating point it loses every digit to
    cancellation from n ~ 40 on (its coefficients reach 1e17 at n = 60); :func:`zernike_radial`
    is what the deformations evaluate."""
    m = abs(m)
    return tuple(
        (n - 2 * s, (-1) ** s * math.factorial(n - s)
         / (math.factorial(s) * math.factorial((n + m) // 2 - s) * math.factorial((n - m) // 2 - s)))
        for s in range((n - m) // 2 + 1))


def _radial_family(m: int, k_max: int, rho: Array, gradient: bool) -> Iterator[tuple[Array, Array | None]]:
    """For k = 0 .. ``k_max``: Q = R_{m+2k}^m(rho) / rho^m and, with ``gradient``, dQ/dx at
    x = 1 - 2 rho^2 (else None), by the three-term recurrence of the Jacobi polynomials
    (Q_k = (-1)^k P_k^(m,0)(x)), which is stable for rho <= 1 at any order, unlike the explicit
    sum."""
    a = float(m)
    x = 1.0 - 2.0 * rho * rho
    q_prev, dq_prev = np.ones_like(rho), np.zeros_like(rho)  # k = 0
    yield q_prev, (dq_prev if gradient else None)
    if k_max < 1:
        return
    q, dq = -0.5 * ((a + 2.0) * x + a), np.full_like(rho, -0.5 * (a + 2.0))  # k = 1
    yield q, (dq if gradient else None)
    for k in range(2, k_max + 1):
        # 2k(k+a)(2k+a-2) P_k = (2k+a-1)[(2k+a)(2k+a-2) x + a^2] P_{k-1}
        #                       - 2(k+a-1)(k-1)(2k+a) P_{k-2}, with P_k = (-1)^k Q_k
        c0 = 2.0 * k * (k + a) * (2 * k + a - 2)
        b = (2 * k + a - 1) * (2 * k + a) * (2 * k + a - 2) / c0
        c = (2 * k + a - 1) * a * a / c0
        d = 2.0 * (k + a - 1) * (k - 1) * (2 * k + a) / c0
        q_next = -(b * x + c) * q - d * q_prev
        if gradient:
            dq, dq_prev = -(b * x + c) * dq - b * q - d * dq_prev, dq
        q, q_prev = q_next, q
        yield q, (dq if gradient else None)


def _radial_terms(orders: Iterable[tuple[int, int]], rho: Array, gradient: bool
                  ) -> dict[tuple[int, int], tuple[Array, Array | None, Array | None]]:
    """(R, dR/drho, R/rho) of R_n^m at ``rho`` for each (n, m >= 0) of ``orders``, one
    recurrence per m (the derivatives None unless ``gradient``; R/rho is 0 for m = 0, where
    nothing uses it)."""
    wanted: dict[int, set[int]] = {}
    for n, m in orders:
        wanted.setdefault(m, set()).add((n - m) // 2)
    out: dict[tuple[int, int], tuple[Array, Array | None, Array | None]] = {}
    for m, ks in wanted.items():
        rho_m1 = rho ** (m - 1) if m >= 1 else None
        rho_m = rho_m1 * rho if rho_m1 is not None else np.ones_like(rho)
        for k, (q, dq_dx) in enumerate(_radial_family(m, max(ks), rho, gradient)):
            if k not in ks:
                continue
            if not gradient:
                out[(m + 2 * k, m)] = (rho_m * q, None, None)
                continue
            dq = -4.0 * rho * dq_dx  # dQ/drho
            if rho_m1 is None:
                out[(2 * k, 0)] = (q, dq, np.zeros_like(rho))
            else:
                out[(m + 2 * k, m)] = (rho_m * q, m * rho_m1 * q + rho_m * dq, rho_m1 * q)
    return out


def zernike_radial(n: int, m: int, rho: ArrayLike, gradient: bool = False
                   ) -> tuple[Array, Array | None, Array | None]:
    """The Zernike radial polynomial R_n^|m|(rho) (un-normalised, R(1) = 1) at ``rho``
    (dimensionless, the radius over the disk's), evaluated stably at any order; with
    ``gradient`` also dR/drho and R/rho (0 for m = 0), else None, None."""
    m = abs(m)
    if n < 0 or m > n or (n - m) % 2:
        raise SceneError(f"Zernike (n={n}, m={m}) does not exist: need |m| <= n, n - |m| even")
    rho = np.asarray(rho, dtype=np.float64)
    return _radial_terms([(n, m)], rho, gradient)[(n, m)]


def noll_norm(n: int, m: int) -> float:
    """Noll normalisation factor sqrt((2 - delta_m0) (n + 1)): each term's RMS over the disk
    is then its coefficient."""
    return math.sqrt((1.0 if m == 0 else 2.0) * (n + 1))


@dataclass(frozen=True)
class Zernike(Deformation):
    """Zernike terms over the disk of radius ``radius`` (m), Noll-normalised.

    ``terms`` holds (n, m, coefficient in metres); m >= 0 takes cos(m phi), m < 0 sin(|m| phi);
    each term's RMS over the disk equals its coefficient; n is at most
    :data:`MAX_ZERNIKE_ORDER`. The radial polynomials (one stable Jacobi recurrence per |m|, see
    :func:`zernike_radial`) and the harmonics cos(m phi), sin(m phi) are formed once per call (by
    recurrence from x / r, y / r) and reused across terms: a spectrum of 25 terms on the 424 000
    vertices of the paper's mesh costs tens of milliseconds.
    """

    terms: tuple[tuple[int, int, float], ...]
    radius: float

    def __post_init__(self) -> None:
        for n, m, _ in self.terms:
            if n < 0 or abs(m) > n or (n - abs(m)) % 2:
                raise SceneError(f"Zernike (n={n}, m={m}) does not exist: need |m| <= n, n - |m| even")
            if n > MAX_ZERNIKE_ORDER:
                raise SceneError(f"Zernike (n={n}, m={m}): radial order n is over "
                                 f"{MAX_ZERNIKE_ORDER}, finer than a scan resolves")

    def factors(self, x, y, gradient: bool) -> Iterator[ZernikeFactors]:
        """Per term, in order, what it contributes at (x, y) before its coefficient: (R(rho),
        the angular factor, and with ``gradient`` the brackets that d/dx and d/dy multiply by
        coefficient * norm / radius; else None, None). They depend on the points and the
        term's (n, m) only, so a caller may keep them for a fixed set of points (a mesh's
        vertices traced for many spectra)."""
        x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        r = np.hypot(x, y)
        rho = r / self.radius
        radials = _radial_terms({(n, abs(m)) for n, m, _ in self.terms}, rho, gradient)
        safe = np.where(r > 0, r, 1.0)
        c1 = np.where(r > 0, x / safe, 1.0)  # cos(phi); phi = 0 at r = 0
        s1 = np.where(r > 0, y / safe, 0.0)
        harmonics = [(np.ones_like(rho), np.zeros_like(rho))]  # (cos m phi, sin m phi)
        for _ in range(max((abs(m) for _, m, _ in self.terms), default=0)):
            c, s = harmonics[-1]
            harmonics.append((c * c1 - s * s1, s * c1 + c * s1))
        for n, m, _ in self.terms:
            am = abs(m)
            c, s = harmonics[am]
            ang, dang = (c, -am * s) if m >= 0 else (s, am * c)
            R, dR, R_over = radials[(n, am)]
            if not gradient:
                yield R, ang, None, None
                continue
            # d/dx = cos(phi) d/dr - sin(phi)/r d/dphi, d/dr = (1/radius) d/drho; R/rho is
            # finite for m >= 1 and 0 for m = 0 (where dang = 0)
            yield R, ang, dR * ang * c1 - R_over * dang * s1, dR * ang * s1 + R_over * dang * c1

    def evaluate(self, x, y, gradient: bool, factors: Iterable[ZernikeFactors] | None = None):
        """(value, d/dx, d/dy) at (x, y) (m; the gradient None unless asked), from the terms'
        ``factors`` when given (as :meth:`factors` yields them at these points)."""
        shape = np.broadcast(np.asarray(x), np.asarray(y)).shape
        value = np.zeros(shape)
        gx = np.zeros(shape) if gradient else None
        gy = np.zeros(shape) if gradient else None
        for (n, m, coef), (R, ang, bx, by) in zip(
                self.terms, self.factors(x, y, gradient) if factors is None else factors, strict=True):
            scale = coef * noll_norm(n, m)
            value += scale * R * ang
            if gradient:
                g = scale / self.radius
                gx += g * bx
                gy += g * by
        return value, gx, gy

    def __call__(self, x, y, panel=None):
        return self.evaluate(x, y, gradient=False)[0]

    def gradient(self, x, y, panel=None):
        _, gx, gy = self.evaluate(x, y, gradient=True)
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
