"""Physical constants (SI), a leaf module: every layer may import it, it imports nothing of raysim.

The speed of light is exact by the definition of the metre; the vacuum permeability is the
CODATA 2018 value (no longer exactly 4 pi 1e-7 H/m since the 2019 SI revision).
"""

from __future__ import annotations

import math

C0 = 299_792_458.0  # speed of light in vacuum (m/s), exact
MU0 = 1.25663706212e-6  # vacuum permeability (H/m), CODATA 2018
EPS0 = 1.0 / (MU0 * C0 * C0)  # vacuum permittivity (F/m), about 8.8542e-12
ETA0 = MU0 * C0  # impedance of free space (Ohm), about 376.73

#: the frequencies (Hz) raysim accepts anywhere (options, scenes, specs, files read back):
#: microwaves of a radio telescope, 1 MHz .. 10 THz
MIN_FREQUENCY_HZ = 1e6
MAX_FREQUENCY_HZ = 1e13


def wavelength(frequency_hz: float) -> float:
    """Free-space wavelength lambda = c / f (m) of a frequency in Hz."""
    return C0 / frequency_hz


def wavenumber(frequency_hz: float) -> float:
    """Free-space wavenumber k = 2 pi f / c (rad/m) of a frequency in Hz."""
    return 2.0 * math.pi * frequency_hz / C0


__all__ = ["C0", "EPS0", "ETA0", "MAX_FREQUENCY_HZ", "MIN_FREQUENCY_HZ", "MU0", "wavelength",
           "wavenumber"]
