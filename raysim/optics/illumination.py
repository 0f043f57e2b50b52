"""The incident plane wave of every wave engine (constants from :mod:`raysim.constants`).

Frame and units of docs/physics.md (reflector frame, metres, SI fields); time convention exp(+j w t).
The wave is E_inc = e_hat exp(-j k k_hat . r) (unit amplitude, V/m) and
H_inc = (k_hat x E_inc) / eta.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.constants import C0, ETA0, MU0

__all__ = ["C0", "ETA0", "MU0", "Illumination", "Taper", "incident_field"]


#: an amplitude taper of the currents over the aperture, (x, y) in m -> dimensionless weight
#: (1 inside, smoothly to 0: lets tests isolate a reflector's interior from its edges)
Taper = Callable[[NDArray, NDArray], NDArray]


@dataclass(frozen=True)
class Illumination:
    """The incident plane wave: wavenumber k (rad/m), unit propagation k_hat, unit E e_hat."""

    k: float
    k_hat: NDArray[np.float64]
    e_hat: NDArray[np.float64]

    @classmethod
    def plane_wave(cls, frequency_hz: float, k_hat: ArrayLike, e_hat: ArrayLike) -> Illumination:
        """The wave at ``frequency_hz`` (Hz) along ``k_hat``, E along ``e_hat`` made normal to it."""
        kh = np.asarray(k_hat, dtype=np.float64)
        kh = kh / np.linalg.norm(kh)
        eh = np.asarray(e_hat, dtype=np.float64)
        eh = eh - (eh @ kh) * kh
        return cls(2.0 * np.pi * frequency_hz / C0, kh, eh / np.linalg.norm(eh))

    @property
    def wavelength(self) -> float:
        """Free-space wavelength (m)."""
        return 2.0 * np.pi / self.k

    @property
    def h_hat(self) -> NDArray[np.float64]:
        """k_hat x e_hat: the direction of H_inc (H_inc = h_hat / eta exp(-j k k_hat . r))."""
        return np.cross(self.k_hat, self.e_hat)


def incident_field(points: ArrayLike, k: float, k_hat: ArrayLike, e_hat: ArrayLike) -> NDArray:
    """E_inc = e_hat exp(-j k k_hat . r) at ``points`` (n, 3) in m: (n, 3) complex, V/m."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    phase = np.exp(-1j * k * (pts @ np.asarray(k_hat, dtype=np.float64)))
    return phase[:, None] * np.asarray(e_hat, dtype=np.float64)[None, :]
