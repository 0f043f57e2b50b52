"""A Zernike series evaluated fast on many points: the dataset's random Zernike spectra.

The same surface as :class:`raysim.surface.deformation.Zernike` (terms (n, m, coefficient in m) over
the disk of radius ``radius`` in m; m >= 0 takes cos(m phi), m < 0 sin(|m| phi); Noll
normalisation, sqrt((2 - delta_m0) (n + 1)), so each term's RMS over the disk is its
coefficient). Where that class raises rho to each power of each term, this one forms the
powers of rho and the harmonics cos(m phi), sin(m phi) once per call and reuses them across
terms: a spectrum of 25 terms on the 424 000 vertices of the paper's mesh costs tens of
milliseconds instead of seconds.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from raysim.surface.deformation import Deformation

Factors = tuple[NDArray, NDArray, NDArray | None, NDArray | None]


@lru_cache(maxsize=512)
def radial_coefficients(n: int, m: int) -> tuple[tuple[int, float], ...]:
    """(power, coefficient) pairs of the radial polynomial R_n^|m|(rho)."""
    m = abs(m)
    return tuple(
        (n - 2 * s, (-1) ** s * math.factorial(n - s)
         / (math.factorial(s) * math.factorial((n + m) // 2 - s) * math.factorial((n - m) // 2 - s)))
        for s in range((n - m) // 2 + 1))


def noll_norm(n: int, m: int) -> float:
    """Noll normalisation factor sqrt((2 - delta_m0) (n + 1))."""
    return math.sqrt((1.0 if m == 0 else 2.0) * (n + 1))


@dataclass(frozen=True)
class ZernikeSeries(Deformation):
    """sum of coef * N_nm R_n^|m|(r / radius) cos|sin(|m| phi) (m), with its gradient."""

    terms: tuple[tuple[int, int, float], ...]
    radius: float

    def __post_init__(self) -> None:
        for n, m, _ in self.terms:
            if n < 0 or abs(m) > n or (n - abs(m)) % 2:
                raise ValueError(f"Zernike (n={n}, m={m}) does not exist: need |m| <= n, n - |m| even")

    def factors(self, x, y, gradient: bool) -> Iterator[Factors]:
        """Per term, in order, what it contributes at (x, y) before its coefficient:
        (R(rho), angular factor, and with ``gradient`` the brackets that d/dx and d/dy
        multiply by coefficient * norm / radius; else None, None). They depend on the points
        and the term's (n, m) only, so a caller may keep them for a fixed set of points."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        x, y = np.broadcast_arrays(x, y)
        rho = np.hypot(x, y) / self.radius
        n_max = max((n for n, _, _ in self.terms), default=0)
        powers = [np.ones_like(rho)]
        for _ in range(n_max):
            powers.append(powers[-1] * rho)
        with np.errstate(invalid="ignore", divide="ignore"):
            r = np.hypot(x, y)
            c1 = np.where(r > 0, x / np.where(r > 0, r, 1.0), 1.0)  # cos(phi); phi = 0 at r = 0
            s1 = np.where(r > 0, y / np.where(r > 0, r, 1.0), 0.0)
        harmonics = [(np.ones_like(rho), np.zeros_like(rho))]  # (cos m phi, sin m phi)
        m_max = max((abs(m) for _, m, _ in self.terms), default=0)
        for _ in range(m_max):
            c, s = harmonics[-1]
            harmonics.append((c * c1 - s * s1, s * c1 + c * s1))
        for n, m, _ in self.terms:
            am = abs(m)
            c, s = harmonics[am]
            ang, dang = (c, -am * s) if m >= 0 else (s, am * c)
            R = sum(k * powers[p] for p, k in radial_coefficients(n, m))
            if not gradient:
                yield R, ang, None, None
                continue
            # dR/drho and R/rho (finite for m >= 1; unused for m = 0 where dang = 0)
            dR = sum(k * p * powers[p - 1] for p, k in radial_coefficients(n, m) if p >= 1)
            R_over = sum(k * powers[p - 1] for p, k in radial_coefficients(n, m) if p >= 1)
            dR = dR if isinstance(dR, np.ndarray) else np.zeros_like(rho)
            R_over = R_over if isinstance(R_over, np.ndarray) else np.zeros_like(rho)
            yield R, ang, dR * ang * c1 - R_over * dang * s1, dR * ang * s1 + R_over * dang * c1

    def evaluate(self, x, y, gradient: bool, factors: Iterable[Factors] | None = None):
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

    def __call__(self, x, y, panel=None) -> NDArray[np.float64]:
        return self.evaluate(x, y, gradient=False)[0]

    def gradient(self, x, y, panel=None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        _, gx, gy = self.evaluate(x, y, gradient=True)
        return gx, gy

    def describe(self) -> str:
        return f"zernike series of {len(self.terms)} terms over r <= {self.radius:g} m"
