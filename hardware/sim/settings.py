"""Settings of the simulated rig (the ``[simulator]`` table of a plan, CLI options on top).

The simulator's truth may differ from what the rig file believes: its track centre offset and
axis zeros are the *true* ones (``None``: the rig file's values, i.e. a perfectly calibrated
rig). Noise and drift are deterministic functions of ``seed`` and the sample index, never of
wall time, so a killed and resumed scan reproduces an uninterrupted one exactly.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any

from hardware.config import Table
from hardware.errors import PlanError
from hardware.rig import Calibration, Rig
from raysim.maps import measurement

# the simulator's bounds: name -> (low, high, the CLI option / plan key that sets it)
BOUNDS: dict[str, tuple[float, float, str]] = {
    "seed": (0, 2**63 - 1, "--seed, [simulator] seed"),
    "noise_db": (0.0, 10.0, "--noise-db, [simulator] noise_db"),
    "drift_db": (0.0, 10.0, "--drift-db, [simulator] drift_db"),
    "gain_db": (-30.0, 30.0, "[simulator] gain_db"),
    "drift_period": (1.0, 1e12, "[simulator] drift_period_samples"),
    "time_scale": (0.0, 1e3, "--time-scale, [simulator] time_scale"),
}


@dataclass(frozen=True)
class SimSettings:
    """Simulated rig settings. Angles in rad, lengths in m, times in s, noise and drift in dB.

    ``noise_db``: standard deviation of each power-meter reading (dB). ``drift_db``: amplitude
    of the slow receiver/source gain drift (dB) since the scan's start, a sinusoid of
    ``drift_period`` samples whose phase follows from ``seed``. ``gain_db``: the receiver's
    absolute gain that the plan's ``power_unit_dbm`` does not know (source flux, cable, probe
    gain): every reading is off by it, so the scan's scale is unknown. The axes move at the
    velocity the driver sets (the rig file's ``speed_deg_s``); ``time_scale`` multiplies
    every move's duration (0: moves are instantaneous, 0.01: a hundred times faster).
    """

    seed: int = 0
    noise_db: float = 0.0
    drift_db: float = 0.0
    drift_period: float = 2000.0
    gain_db: float = 0.0
    centre_offset: tuple[float, float, float] | None = None
    slider_zero: float | None = None
    rotation_zero: float | None = None
    time_scale: float = 1.0

    def __post_init__(self) -> None:
        """The one check of the simulator's settings, whether they come from a plan's
        ``[simulator]`` table, the command line or Python."""
        for name, (lo, hi, option) in BOUNDS.items():
            value = getattr(self, name)
            integer = name == "seed"
            ok = (isinstance(value, int) and not isinstance(value, bool)) if integer else (
                isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value))
            if not ok or not lo <= value <= hi:
                kind = "an integer" if integer else "a number"
                span = f"{lo}..{hi}" if integer else f"{lo:g}..{hi:g}"
                raise PlanError(f"the simulator's {name} ({option}) must be {kind} in {span}, "
                                f"got {value!r}")
        for name in ("slider_zero", "rotation_zero"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and abs(value) <= math.pi):
                raise PlanError(f"the simulator's {name} must lie within +-180 deg, got {value!r}")
        if self.centre_offset is not None and not all(math.isfinite(v) for v in self.centre_offset):
            raise PlanError(f"the simulator's centre_offset must be finite, got {self.centre_offset}")

    def true_rig(self, rig: Rig) -> Rig:
        """The rig as it really is: the file's rig with this simulator's true calibration.
        Its centre offset must lie well inside the track, as the rig file's must: at 0.5 R and
        beyond the probe comes near the focus (a 15 m offset on a 10 m track gave a divide by
        zero and a FieldMap of nothing, exit 0)."""
        if self.centre_offset is not None and math.dist(self.centre_offset, (0, 0, 0)) >= 0.5 * rig.radius:
            raise PlanError(f"the simulator's centre_offset {tuple(self.centre_offset)} m must lie well "
                            f"inside the track: under half its radius ({0.5 * rig.radius:g} m)")
        cal = rig.calibration
        return rig.with_calibration(Calibration(
            centre_offset=cal.centre_offset if self.centre_offset is None else self.centre_offset,
            slider_zero=cal.slider_zero if self.slider_zero is None else self.slider_zero,
            rotation_zero=cal.rotation_zero if self.rotation_zero is None else self.rotation_zero,
        ))

    def record(self) -> dict[str, Any]:
        """The settings as a flat dict (for journals and FieldMap attributes; None -> 'rig')."""
        out: dict[str, Any] = {}
        for key, value in asdict(self).items():
            if value is None:
                out[f"sim_{key}"] = "rig"
            elif isinstance(value, tuple):
                for axis, v in zip("xyz", value, strict=True):
                    out[f"sim_{key}_{axis}"] = float(v)
            else:
                out[f"sim_{key}"] = value
        return out


def sim_settings_from_table(t: Table) -> SimSettings:
    """Parse a ``[simulator]`` table (degrees in ``*_deg`` keys, see ``scenes/scan_demo.toml``);
    the bounds are :data:`BOUNDS`, checked by :class:`SimSettings` itself."""
    offset = t.vector3("centre_offset_m") if t.has("centre_offset_m") else None
    values = {
        "seed": t.integer("seed", 0),
        "noise_db": t.number("noise_db", 0.0),
        "drift_db": t.number("drift_db", 0.0),
        "drift_period": t.number("drift_period_samples", 2000.0),
        "gain_db": t.number("gain_db", 0.0),
        "centre_offset": offset,
        "slider_zero": t.angle("slider_zero_deg") if t.has("slider_zero_deg") else None,
        "rotation_zero": t.angle("rotation_zero_deg") if t.has("rotation_zero_deg") else None,
        "time_scale": t.number("time_scale", 1.0),
    }
    t.done()
    try:
        return SimSettings(**values)
    except PlanError as exc:
        raise t.fail(str(exc)) from exc


def with_options(settings: SimSettings, **options: Any) -> SimSettings:
    """``settings`` with the options that are not None replaced (checked like the table)."""
    return replace(settings, **{k: v for k, v in options.items() if v is not None})


def drift_db(settings: SimSettings, index: int) -> float:
    """Receiver gain drift (dB) at sample ``index`` since the start of the scan (0 at index 0).

    A slow sinusoid of amplitude ``drift_db`` and period ``drift_period`` samples whose phase
    follows from the seed (:func:`raysim.maps.measurement.drift_db`).
    """
    if settings.drift_db == 0.0:
        return 0.0
    phase = (settings.seed * 0.6180339887498949 % 1.0) * 2.0 * math.pi
    return float(measurement.drift_db(settings.drift_db, settings.drift_period, phase, index))
