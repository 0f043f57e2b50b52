"""A simulated rig: the power meter and the motion controller served on loopback TCP sockets.

The rig reads a FieldMap as the field around the focus. When the power meter is triggered, the
probe's true position follows from the motion controller's axes *now* through the simulator's
true calibration (which may differ from the rig file's: a centre offset, zero offsets); the
intensity there comes from the FieldMap (:class:`hardware.interp.SphereField`: its ratio to
the ideal interpolated at the probe's direction, periodic in phi, times the ideal's exact
value there, times (R_map / r)^2 for a probe at distance r from the focus). The reading in
dBm adds the receiver's gain (``power_unit_dbm`` for intensity 1), a slow drift and Gaussian
noise, both in dB and both deterministic functions of the seed and the sample index (the
acquisition announces the index through :meth:`SimulatedRig.set_sample`; the k-th reading of
a sample draws noise number k), so a resumed scan repeats an uninterrupted one exactly. Axes
move at the velocity the driver sets, scaled by the simulator's time scale.

The instruments are real TCP servers on 127.0.0.1 (``TCPIP::127.0.0.1::PORT::SOCKET``), so
the drivers under test go through pyvisa and pyvisa-py exactly as with the real rig.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hardware.interp import SphereField
from hardware.rig import Rig
from hardware.sim.instruments import ESP_VERSION, METER_IDN, Axis, ESP301Model, PowerMeterModel
from hardware.sim.loopback import LineServer
from hardware.sim.settings import SimSettings, drift_db

FLOOR = 1e-12   # intensity floor (shadow, beyond the rim image): -120 dB below the plane wave


@dataclass(frozen=True)
class Faults:
    """Instrument faults to inject (tests): silence, identity, an error, a stalled move.

    ``meter_error_at_reading`` pushes an error into the meter's queue at that reading
    (counting from 1); ``meter_fixed_unit`` ("W" or "DBM") is the unit the meter stays in
    whatever ``UNIT:POW`` sets; ``stall_at_move`` makes that move (from 1) stop halfway.
    """

    meter_silent: bool = False
    motion_silent: bool = False
    meter_idn: str = METER_IDN
    motion_version: str = ESP_VERSION
    meter_error_at_reading: int | None = None
    meter_fixed_unit: str | None = None
    stall_at_move: int | None = None


class SimulatedRig:
    """Both simulated instruments of a rig, answering from a field (or a floor without one).

    Parameters
    ----------
    rig : the rig as its file describes it (axes, limits, park position).
    settings : noise, drift, seed, time scale and the true calibration.
    field : the intensity around the focus; None reads the floor everywhere.
    power_unit_dbm : what the meter reads for intensity 1 (dBm).
    faults : faults to inject.
    """

    def __init__(self, rig: Rig, settings: SimSettings = SimSettings(),
                 field: SphereField | None = None, *, power_unit_dbm: float = -20.0,
                 faults: Faults = Faults()) -> None:
        self.rig = rig
        self.truth = settings.true_rig(rig)
        self.settings = settings
        self.field = field
        self.power_unit_dbm = power_unit_dbm
        lim = rig.limits
        park = dict(zip((rig.slider_axis, rig.rotation_axis), rig.park, strict=True))
        limits = {rig.slider_axis: (lim.slider_min, lim.slider_max),
                  rig.rotation_axis: (lim.rotation_min, lim.rotation_max)}
        axes = {n: Axis(start=math.degrees(park[n]), target=math.degrees(park[n]),
                        low=math.degrees(limits[n][0]), high=math.degrees(limits[n][1]))
                for n in park}
        self.motion = ESP301Model(axes, time_scale=settings.time_scale,
                                  stall_at_move=faults.stall_at_move,
                                  version=faults.motion_version)
        self.meter = PowerMeterModel(self.power_dbm, idn=faults.meter_idn,
                                     error_at_reading=faults.meter_error_at_reading,
                                     fixed_unit=faults.meter_fixed_unit)
        self._index = 0
        self._reading = 0
        silent = {"meter": faults.meter_silent, "motion": faults.motion_silent}
        self.servers = {
            "meter": LineServer(_quiet if silent["meter"] else self.meter.handle,
                                name="sim-meter", terminator="\n"),
            "motion": LineServer(_quiet if silent["motion"] else self.motion.handle,
                                 name="sim-esp301", terminator="\r\n"),
        }

    @property
    def resources(self) -> dict[str, str]:
        """VISA resource names by role (``meter``, ``motion``); valid after :meth:`start`."""
        return {role: server.resource for role, server in self.servers.items()}

    def start(self) -> SimulatedRig:
        """Start both servers on ephemeral loopback ports; return self."""
        for server in self.servers.values():
            server.start()
        return self

    def stop(self) -> None:
        """Stop both servers (bounded wait)."""
        for server in self.servers.values():
            server.stop()

    def __enter__(self) -> SimulatedRig:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def set_sample(self, index: int) -> None:
        """Announce the sample index; noise and drift of the next readings follow from it."""
        self._index = index
        self._reading = 0

    def probe(self) -> tuple[float, float, float]:
        """The probe's true (theta, phi) in rad and distance r from the focus in m, now."""
        slider = math.radians(self.motion.position(self.rig.slider_axis))
        rotation = math.radians(self.motion.position(self.rig.rotation_axis))
        return self.truth.probe(slider, rotation)

    def intensity(self, theta: float, phi: float, r: float) -> float:
        """Intensity relative to the incident wave at the point (theta, phi, r) (rad, m)."""
        if self.field is None:
            return FLOOR
        return max(self.field(theta, phi, r), FLOOR)

    def power_dbm(self) -> float:
        """What the meter reads now (dBm): field, gain, drift and noise of this reading."""
        true_db = 10.0 * math.log10(self.intensity(*self.probe()))
        noise = 0.0
        if self.settings.noise_db > 0.0:
            rng = np.random.default_rng([self.settings.seed, self._index, self._reading])
            noise = self.settings.noise_db * float(rng.standard_normal())
        self._reading += 1
        return (self.power_unit_dbm + self.settings.gain_db + true_db
                + drift_db(self.settings, self._index) + noise)


def _quiet(line: str) -> None:
    """A silent instrument: takes every line, answers none."""
    return None
