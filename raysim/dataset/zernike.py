"""The dataset's random Zernike spectra: :class:`raysim.surface.deformation.Zernike`, named briefly.

One evaluator serves scenes and datasets (powers of rho and the harmonics formed once per call
and reused across terms, so a spectrum of 25 terms on the paper's mesh costs tens of
milliseconds); this module keeps the dataset's names for it.
"""

from __future__ import annotations

from dataclasses import dataclass

from raysim.surface.deformation import Zernike, noll_norm, radial_coefficients
from raysim.surface.deformation import ZernikeFactors as Factors


@dataclass(frozen=True)
class ZernikeSeries(Zernike):
    """A :class:`~raysim.surface.deformation.Zernike` sum that describes itself in one line
    (a random spectrum has dozens of terms)."""

    def describe(self) -> str:
        return f"zernike series of {len(self.terms)} terms over r <= {self.radius:g} m"


__all__ = ["Factors", "ZernikeSeries", "noll_norm", "radial_coefficients"]
