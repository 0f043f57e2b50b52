"""The scan's gain: known or estimated, and the one surface shape an unknown gain leaves open.

Frame and units (docs/physics.md): aperture x, y and delta in m, intensities relative to the
incident plane wave, FA dimensionless.

A scale error c of the readings (I' = c I) turns FA into (1 + FA) / c - 1, to first order
FA + epsilon with the constant epsilon = 1/c - 1. The Poisson solve turns a constant FA into
one shape delta_c, zero on the rim: it cannot be seen in the intensities, with or without rim
targets (it vanishes there), just as the harmonic part cannot be seen without rim targets.

- The linear answer is linear in FA, so its delta_c is its response to FA = 1:
  G Laplacian(delta_c) = 1 (times the amplitude weight where the FA is weighted).
- A model-based answer converges to the forward model's own response to a constant FA. For
  the GO model that is a refocus: delta_c = (a^2 - r^2) / kappa with
  kappa = 2 (4 F^2 + a^2) / R - 8 F = 8 F d(a) / R, the paraboloid whose FA is 1 at the rim
  image (checked against exact GO data with a scale error of 1e-4 in tests/solver).

Both are normalised to a unit FA offset, so the coefficient of delta_c in a map is the FA
offset epsilon of its data: a scan read 1e-4 too high gives epsilon = -1e-4.

Gain modes: ``known`` trusts the scale (simulated data carry an absolute incident intensity);
``power`` estimates it from GO power conservation and removes delta_c from the map (its
coefficient recorded); ``auto`` is ``known`` for simulated FieldMaps and ``power`` for
measured scans (FieldMap ``method`` = ``measured``). ``none`` is the former name of ``known``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from raysim.maps.sphere import SphereGrid
from solver.aperture import ApertureGrid
from solver.equation import power_gain
from solver.errors import SolverError
from solver.resample import fill_missing

MEASURED = "measured"  # the FieldMap method of a scan read by a rig
#: a trusted scale is refused when the scan holds less than 1/this or more than this times the
#: ideal's total power: a surface error redistributes the power on the sphere, it does not
#: halve or double it (the paper's 3 mm deformation moves the balance by under 1 %); such a
#: scan's readings are on another scale (watts, another reference)
MAX_TRUSTED_POWER_RATIO = 2.0


@dataclass(frozen=True)
class GainChoice:
    """Whether the scan's scale is trusted or estimated, and why (for the SurfaceMap)."""

    mode: str        # the mode asked for: auto, known, power or none
    estimated: bool  # True: estimated from the power balance, delta_c removed
    reason: str


def resolve_gain(mode: str, method: str) -> GainChoice:
    """The gain treatment of ``mode`` for data of FieldMap ``method`` (see the module)."""
    if mode == "auto":
        measured = method == MEASURED
        why = ("auto: a measured scan's absolute scale is not known" if measured else
               f"auto: simulated data ({method or 'unknown method'}) carry an absolute incident "
               "intensity")
        return GainChoice(mode, measured, why)
    if mode == "power":
        return GainChoice(mode, True, "asked for: estimated from the power balance")
    return GainChoice(mode, False, "asked for: the scan's scale is trusted")


@dataclass(frozen=True)
class GainEstimate:
    """A scan's scale c from GO power conservation, with its spread and coverage.

    ``std``: the standard deviation of c from the readings' noise (relative variance v per
    sample, or the scan's own ``intensity_std``); ``coverage``: the share of the ideal
    reflected power that falls in scanned, usable cells (1 when nothing is missing).
    """

    scale: float
    std: float
    coverage: float


@dataclass(frozen=True)
class MeasuredFA:
    """FA of a scan after its gain, with the noise bias removed (NaN where a sample is missing).

    ``gain``: whether the scale was trusted or estimated; ``estimate``: the scale divided out
    (1 when trusted), its spread and coverage; ``noise_variance``: the relative variance v of
    the readings and where it came from; ``n_rows``: the usable theta rows; ``missing``:
    missing samples among them.
    """

    fa: NDArray[np.float64]
    gain: GainChoice
    estimate: GainEstimate
    noise_variance: float
    noise_source: str
    n_rows: int
    missing: int

    @property
    def scale(self) -> float:
        """The scale divided out of the readings (1 when the gain is trusted)."""
        return self.estimate.scale


def check_trusted_scale(intensity: NDArray[np.float64], intensity_ideal: NDArray[np.float64],
                        sphere: SphereGrid, choice: GainChoice) -> None:
    """Refuse (SolverError) a trusted gain whose scan's total power is not the ideal's within
    :data:`MAX_TRUSTED_POWER_RATIO`: its FA would be a huge constant, read as a huge surface."""
    c = power_gain(intensity, intensity_ideal, sphere.cell_area())
    if 1.0 / MAX_TRUSTED_POWER_RATIO <= c <= MAX_TRUSTED_POWER_RATIO:
        return
    raise SolverError(f"the gain is trusted (gain {choice.mode!r}), but the scan holds "
                      f"{c:.3g} times the ideal's total power: its intensity is not on the ideal's "
                      "scale (readings in W, or against another reference?); estimate the scale "
                      "with gain 'power' (raysim invert --gain power)")


def estimate_gain(intensity: NDArray[np.float64], intensity_ideal: NDArray[np.float64],
                  sphere: SphereGrid, n_rows: int, v: float,
                  intensity_std: NDArray[np.float64] | None = None) -> GainEstimate:
    """The scan's scale c = sum(I A) / sum(I_ideal A) over the sphere, holes filled first.

    A missing sample would drop its cell from both power sums and bias c by its FA; inside
    the ``n_rows`` usable rows it takes the inpainted ratio I / I_ideal, beyond them the
    ideal. The spread: c is a weighted sum of independent readings, so
    var(c) = sum((A sigma_i)^2) / sum(A I_ideal)^2 with sigma_i = std_i or sqrt(v) I_i (also
    where std_i is NaN: one reading states no spread, never a spread of zero); NaN when the
    noise is not known at all (v NaN): no standard error rather than a false one.
    """
    area = np.broadcast_to(sphere.cell_area(), intensity.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(intensity_ideal > 0, intensity / intensity_ideal, np.nan)
    ratio[:n_rows], _ = fill_missing(ratio[:n_rows], n_rows)
    seen = np.isfinite(intensity)
    filled = np.where(seen, intensity, np.where(np.isfinite(ratio), ratio, 1.0) * intensity_ideal)
    scale = power_gain(filled, intensity_ideal, area)
    total = float(np.sum(np.where(np.isfinite(intensity_ideal), intensity_ideal, 0.0) * area))
    if not total > 0:
        return GainEstimate(scale, 0.0, 0.0)
    used = seen.copy()
    used[n_rows:] = False
    from_noise = np.sqrt(v) * np.where(seen, intensity, 0.0)  # NaN when v is unknown
    # a point of one reading states no spread (NaN): its sigma comes from the noise v instead
    sigma = (np.where(np.isfinite(intensity_std), intensity_std, from_noise) if intensity_std is not None
             else from_noise)
    std = float(np.sqrt(np.sum((area * sigma)[used] ** 2))) / total
    coverage = float(np.sum((intensity_ideal * area)[used & np.isfinite(intensity_ideal)])) / total
    return GainEstimate(scale, std, coverage)


def refocus_mode(grid: ApertureGrid, F: float, R: float) -> NDArray[np.float64]:
    """delta_c of a model-based answer (m per unit FA offset): (a^2 - r^2) / kappa, NaN outside."""
    kappa = 2.0 * (4.0 * F * F + grid.a ** 2) / R - 8.0 * F
    return grid.masked((grid.a ** 2 - grid.r ** 2) / kappa)
