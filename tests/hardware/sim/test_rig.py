"""The simulated rig through the real PyVISA socket path: readings, calibration, noise, faults."""

from __future__ import annotations

import math
import socket
import time

import numpy as np
import pytest

from hardware.acquire import move_to
from hardware.interp import FieldSampler, SphereField
from hardware.rig import Rig
from hardware.session import open_instruments
from hardware.sim.rig import Faults, SimulatedRig
from hardware.sim.settings import SimSettings, drift_db
from raysim.errors import InstrumentError
from raysim.maps.sphere import SphereGrid

GRID = SphereGrid(10.0, 18, 36)
RIG = Rig(radius=10.0, visa_timeout_s=0.3, move_timeout_s=2.0)


F, D = 33.0, 110.0


def bilinear(theta, phi):
    """A ratio to the ideal that bilinear interpolation reproduces exactly (rad in)."""
    return 1.02 + 0.04 * theta + 0.001 * phi + 0.005 * theta * phi


def ideal(theta: float) -> float:
    """(rho / R)^2 of the ideal paraboloid, written out: rho = 2F / (1 + cos theta)."""
    return (2 * F / (1 + math.cos(theta)) / 10.0) ** 2


def sampler(fn=bilinear) -> SphereField:
    t, p = np.meshgrid(GRID.theta, GRID.phi, indexing="ij")
    return SphereField(FieldSampler(fn(t, p), GRID), F, D)


def test_reading_is_the_field_at_the_commanded_cell() -> None:
    settings = SimSettings(time_scale=0.0)
    with SimulatedRig(RIG, settings, sampler(), power_unit_dbm=-20.0) as sim:
        inst = open_instruments(sim.resources, RIG)
        inst.meter.setup(3e8)
        inst.motion.setup((1, 2), RIG.speed)
        for i, j in ((2, 3), (10, 20), (15, 35)):
            theta, phi = GRID.theta[i], GRID.phi[j]
            move_to(inst.motion, RIG, *RIG.axes(theta, phi))
            expected = -20.0 + 10 * math.log10(bilinear(theta, phi) * ideal(theta))
            assert inst.meter.read_dbm() == pytest.approx(expected, abs=1e-8)
        inst.close()


def test_reading_follows_the_true_track_centre() -> None:
    """The rig file says the track is centred on the focus; it is 2 mm off along x and z.
    The probe then sits elsewhere: the reading is the field there times (R / r)^2."""
    offset = np.array([0.002, 0.0, 0.002])
    settings = SimSettings(time_scale=0.0, centre_offset=tuple(offset))
    with SimulatedRig(RIG, settings, sampler(), power_unit_dbm=0.0) as sim:
        inst = open_instruments(sim.resources, RIG)
        inst.meter.setup(3e8)
        inst.motion.setup((1, 2), RIG.speed)
        for theta_deg, phi_deg in ((20.0, 40.0), (55.0, 300.0)):
            theta, phi = math.radians(theta_deg), math.radians(phi_deg)
            s, a = RIG.axes(theta, phi)
            move_to(inst.motion, RIG, s, a)
            u = np.array([math.sin(s) * math.cos(a), math.sin(s) * math.sin(a), -math.cos(s)])
            p = offset + 10.0 * u
            r = float(np.linalg.norm(p))
            t_true = math.atan2(math.hypot(p[0], p[1]), -p[2])
            p_true = math.atan2(p[1], p[0]) % (2 * math.pi)
            expected = 10 * math.log10(bilinear(t_true, p_true) * ideal(t_true)
                                       * (10.0 / r) ** 2)
            got = inst.meter.read_dbm()
            assert got == pytest.approx(expected, abs=1e-8)
            # and the offset matters at the level the method needs (> 1e-4 in the ratio)
            assert abs(got - 10 * math.log10(bilinear(theta, phi) * ideal(theta))) > 4e-4
        inst.close()


def test_noise_is_a_function_of_seed_and_index() -> None:
    settings = SimSettings(time_scale=0.0, noise_db=0.05, seed=11)
    field = sampler(lambda t, p: np.ones_like(t))

    def readings(index: int, count: int) -> list[float]:
        with SimulatedRig(RIG, settings, field) as sim:
            sim.set_sample(index)
            return [sim.power_dbm() for _ in range(count)]

    first = readings(7, 3)
    assert readings(7, 3) == first
    assert readings(8, 3) != first
    assert len(set(first)) == 3
    with SimulatedRig(RIG, SimSettings(time_scale=0.0), field) as sim:
        base = sim.power_dbm()
    with SimulatedRig(RIG, settings, field) as sim:
        draws = []
        for index in range(1500):
            sim.set_sample(index)
            draws.append(sim.power_dbm() - base)
    assert np.mean(draws) == pytest.approx(0.0, abs=4 * 0.05 / math.sqrt(1500))
    assert np.std(draws) == pytest.approx(0.05, rel=0.08)


def test_drift_starts_at_zero_and_repeats() -> None:
    settings = SimSettings(drift_db=0.3, drift_period=50.0, seed=4)
    values = [drift_db(settings, n) for n in range(200)]
    assert values[0] == 0.0
    assert max(abs(v) for v in values) <= 0.6
    assert max(values) - min(values) > 0.3
    assert values[17] == pytest.approx(values[67], abs=1e-12)
    assert drift_db(SimSettings(drift_db=0.0), 33) == 0.0


def test_unreachable_instrument() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(InstrumentError, match="unreachable"):
        open_instruments({"meter": f"TCPIP::127.0.0.1::{port}::SOCKET",
                          "motion": f"TCPIP::127.0.0.1::{port}::SOCKET"}, RIG)


@pytest.mark.parametrize(("faults", "message"), [
    (Faults(meter_silent=True), r"power meter .* is silent: no answer to '\*IDN\?' within 0.3 s"),
    (Faults(motion_silent=True), r"motion controller .* is silent: no answer to 'VE\?'"),
    (Faults(meter_idn="Keysight Technologies,E4416A,1,1"), r"expected a Keysight N1913A"),
    (Faults(motion_version="SMC100 Version 1"), r"expected a Newport ESP301"),
])
def test_identity_faults(faults: Faults, message: str) -> None:
    with SimulatedRig(RIG, SimSettings(time_scale=0.0), faults=faults) as sim:
        start = time.monotonic()
        with pytest.raises(InstrumentError, match=message):
            open_instruments(sim.resources, RIG)
        assert time.monotonic() - start < 2.0


def test_servers_stop_promptly_with_clients_connected() -> None:
    sim = SimulatedRig(RIG, SimSettings(time_scale=0.0)).start()
    inst = open_instruments(sim.resources, RIG)
    start = time.monotonic()
    sim.stop()
    assert time.monotonic() - start < 1.0
    with pytest.raises(InstrumentError):
        inst.meter.read_dbm()
    inst.close()


def test_motion_takes_time() -> None:
    """A 30 deg move at 10 deg/s with time scale 0.05 takes 0.15 s."""
    with SimulatedRig(RIG, SimSettings(time_scale=0.05)) as sim:
        inst = open_instruments(sim.resources, RIG)
        rig = Rig(radius=10.0, speed=math.radians(10.0), park=RIG.park)
        inst.motion.setup((1, 2), rig.speed)
        start = time.monotonic()
        move_to(inst.motion, rig, math.radians(65.0), 0.0)
        elapsed = time.monotonic() - start
        assert 0.14 < elapsed < 0.6
        inst.close()
