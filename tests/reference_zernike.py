"""An independent Zernike reference for the tests: radial polynomials from Jacobi polynomials.

R_n^m(rho) = (-1)^((n - m)/2) rho^m P_((n - m)/2)^(m, 0)(1 - 2 rho^2) (Born & Wolf, Principles
of Optics, 9.2), with scipy's Jacobi polynomials: no code shared with raysim's evaluator.
"""

from __future__ import annotations

import numpy as np
from scipy.special import eval_jacobi


def radial(n: int, m: int, rho):
    """R_n^|m|(rho) for rho >= 0."""
    m = abs(m)
    k = (n - m) // 2
    rho = np.asarray(rho, dtype=np.float64)
    return (-1.0) ** k * rho**m * eval_jacobi(k, m, 0, 1.0 - 2.0 * rho * rho)


def zernike_sum(terms, a: float, x, y):
    """sum of c sqrt((2 - delta_m0)(n + 1)) R_n^|m|(r / a) cos(m phi) | sin(|m| phi) (m < 0)."""
    rho, phi = np.hypot(x, y) / a, np.arctan2(y, x)
    out = np.zeros_like(rho)
    for n, m, c in terms:
        angular = np.cos(m * phi) if m >= 0 else np.sin(-m * phi)
        out += c * np.sqrt((2 - (m == 0)) * (n + 1)) * radial(n, m, rho) * angular
    return out
