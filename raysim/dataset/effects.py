"""Measurement effects of a dataset: what a real scan adds to a simulated intensity.

A spec's optional ``[measurement]`` table gives the law of each effect (a number, or a law of
:mod:`raysim.dataset.distributions`); every sample draws its own values, which the store keeps
beside it (``measure_<key>``), and stores the measured intensity ``intensity_measured`` next
to the clean ``intensity``, so one store trains a model on either. The effects, in the order
a scan meets them (the rig's physics, :mod:`raysim.maps.measurement` and
:mod:`raysim.maps.interp`, shared with the simulated rig of ``hardware.sim``):

- ``centre_offset_mm``: the track's centre is off the focus by (x, y, z), each component drawn
  from the law (mm in the spec, m in the store). The probe that believes it is at the cell
  centre (theta, phi) on the sphere of radius R really is at (theta', phi', r); it reads the
  clean value times the field's change between the two points, the field between cell
  centres being the interpolated ratio to the ideal times the exact ideal, times (R / r)^2;
- ``gain_db``: an unknown scale of the whole scan (dB): source flux, cable, probe gain;
- ``drift_db``, ``drift_period_points``: a slow gain drift A (sin(2 pi n / P + p) - sin p)
  along the scan's order n (the rig's serpentine: one theta sweep per phi line), amplitude A
  (dB) and period P (points) drawn, phase p uniform, left in the data as recorded (no
  reference readings to remove it);
- ``noise_db``, ``readings``: each point is the linear mean of ``readings`` power-meter
  readings, each with Gaussian noise of ``noise_db`` standard deviation in dB;
- ``missing_fraction``: each point is lost (NaN) with this probability.

Why the measured intensity is stored and not only its parameters: the store then holds
exactly the data a model trained on, whatever numpy's random streams become in later
releases, and a loader reads it at I/O speed; the parameters stay beside it, and
:func:`apply` with the sample's realisation seed regenerates it. A spec without the table
makes the store of before, bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from raysim.dataset.distributions import Distribution, parse_distribution
from raysim.maps import measurement
from raysim.maps.interp import FieldSampler, SphereField
from raysim.maps.sphere import SphereGrid

# key -> (default, bounds (lo, hi; None: any sign, a normal law allowed), integer, factor to SI)
_KEYS: dict[str, tuple[float, tuple[float | None, float | None], bool, float]] = {
    "noise_db": (0.0, (0.0, 10.0), False, 1.0),
    "readings": (1, (1, 10_000), True, 1.0),
    "gain_db": (0.0, (None, None), False, 1.0),
    "centre_offset_mm": (0.0, (None, None), False, 1e-3),
    "drift_db": (0.0, (0.0, 10.0), False, 1.0),
    "drift_period_points": (1e4, (1.0, 1e9), False, 1.0),
    "missing_fraction": (0.0, (0.0, 0.5), False, 1.0),
}
# the per-sample values the store keeps: name -> (units, meaning)
VARIABLES: dict[str, tuple[str, str]] = {
    "noise_db": ("dB", "standard deviation of one power-meter reading"),
    "readings": ("1", "readings averaged per point"),
    "gain_db": ("dB", "unknown gain of the whole scan"),
    "offset_x": ("m", "track centre offset from the focus, x"),
    "offset_y": ("m", "track centre offset from the focus, y"),
    "offset_z": ("m", "track centre offset from the focus, z"),
    "drift_db": ("dB", "gain drift amplitude A of A (sin(2 pi n / P + p) - sin p)"),
    "drift_period": ("1", "gain drift period P in scan points"),
    "drift_phase": ("rad", "gain drift phase p"),
    "missing_fraction": ("1", "probability that a point is missing"),
}
PREFIX = "measure_"


@dataclass(frozen=True)
class Measurement:
    """The laws of a dataset's measurement effects (SI: the centre offset in m)."""

    noise_db: Distribution
    readings: Distribution
    gain_db: Distribution
    centre_offset: Distribution  # m, each of x, y, z
    drift_db: Distribution
    drift_period: Distribution  # points
    missing_fraction: Distribution

    def draw(self, rng: np.random.Generator) -> dict[str, Any]:
        """One sample's effect values (keys of :data:`VARIABLES`)."""
        offset = [float(self.centre_offset.draw(rng)) for _ in range(3)]
        return {"noise_db": float(self.noise_db.draw(rng)), "readings": int(self.readings.draw(rng)),
                "gain_db": float(self.gain_db.draw(rng)),
                "offset_x": offset[0], "offset_y": offset[1], "offset_z": offset[2],
                "drift_db": float(self.drift_db.draw(rng)),
                "drift_period": float(self.drift_period.draw(rng)),
                "drift_phase": float(rng.uniform(0.0, 2.0 * math.pi)),
                "missing_fraction": float(self.missing_fraction.draw(rng))}


def parse_measurement(table: Any, where: str = "measurement") -> Measurement:
    """A :class:`Measurement` from the spec's ``[measurement]`` table (ValueError if bad)."""
    if not isinstance(table, dict):
        raise ValueError(f"'{where}' must be a table of measurement effects")
    for key in table:
        if key not in _KEYS:
            raise ValueError(f"unknown key '{where}.{key}' (known: {', '.join(_KEYS)})")
    laws = {}
    for key, (default, (lo, hi), integer, factor) in _KEYS.items():
        dist = parse_distribution(table.get(key, default), f"{where}.{key}", lo=lo, hi=hi,
                                  integer=integer)
        laws[key] = Distribution(dist.law, dist.a * factor, dist.b * factor) if factor != 1.0 else dist
    return Measurement(noise_db=laws["noise_db"], readings=laws["readings"], gain_db=laws["gain_db"],
                       centre_offset=laws["centre_offset_mm"], drift_db=laws["drift_db"],
                       drift_period=laws["drift_period_points"],
                       missing_fraction=laws["missing_fraction"])


def probed(clean: NDArray, ideal: NDArray, sphere: SphereGrid, F: float, D: float,
           offset: tuple[float, float, float]) -> NDArray[np.float64]:
    """The clean intensity as a probe on a track centred at ``offset`` (m) reads it.

    The value at each believed cell centre is the clean one times the field's change from that
    centre to the probe's true point (:class:`raysim.maps.interp.SphereField`); a cell the
    ideal leaves dark takes the field at the true point. A zero offset returns ``clean``.
    """
    clean = np.asarray(clean, dtype=np.float64)
    if not any(offset):
        return clean
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(ideal > 0, clean / ideal, np.nan)
    for i in range(1, ratio.shape[0]):  # beyond the rim image: the last lit row's ratio
        dark = ~(ideal[i] > 0)
        ratio[i, dark] = ratio[i - 1, dark]
    field = SphereField(FieldSampler(ratio, sphere), F, D)
    theta, phi = np.meshgrid(sphere.theta, sphere.phi, indexing="ij")
    true = field.values(*measurement.probe_point(theta, phi, sphere.radius, offset))
    believed = field.values(theta, phi, sphere.radius)
    with np.errstate(divide="ignore", invalid="ignore"):
        change = np.where(believed > 0, true / believed, np.nan)
    return np.where(believed > 0, clean * change, true)


def apply(clean: NDArray, ideal: NDArray, sphere: SphereGrid, F: float, D: float,
          values: dict[str, Any], rng: np.random.Generator) -> NDArray[np.float64]:
    """The measured intensity (n_theta, n_phi) of one sample: ``clean`` (relative to the
    incident wave) with the effect ``values`` (a :meth:`Measurement.draw`) applied; ``rng``
    draws the noise and the missing points. With no effect it returns ``clean``'s values."""
    offset = (values["offset_x"], values["offset_y"], values["offset_z"])
    true = probed(clean, ideal, sphere, F, D, offset)
    order = measurement.serpentine_order(sphere.n_theta, sphere.n_phi)
    gain_db = values["gain_db"] + measurement.drift_db(values["drift_db"], values["drift_period"],
                                                       values["drift_phase"], order)
    k = int(values["readings"])
    noise = values["noise_db"] * rng.standard_normal((k, *true.shape))
    factor = np.mean(10.0 ** ((gain_db + noise) / 10.0), axis=0)
    measured = true * factor
    lost = rng.random(true.shape) < values["missing_fraction"]
    measured[lost] = np.nan
    return measured
