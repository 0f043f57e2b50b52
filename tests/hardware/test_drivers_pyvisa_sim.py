"""The drivers' command strings against pyvisa-sim models written from the manuals."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import pyvisa

from hardware.instruments.motion import MotionController
from hardware.instruments.power_meter import PowerMeter
from raysim.errors import InstrumentError

YAML = Path(__file__).with_name("instruments.yaml")


@pytest.fixture
def rm() -> pyvisa.ResourceManager:
    manager = pyvisa.ResourceManager(f"{YAML}@sim")
    yield manager
    manager.close()


def test_meter_setup_and_reading(rm: pyvisa.ResourceManager) -> None:
    meter = PowerMeter.open("TCPIP::meter.example::5025::SOCKET", rm=rm, timeout_s=0.5)
    meter.setup(3.0e8)
    assert meter.link.query("SENS:FREQ?") == "+3.000000E+08"
    assert meter.link.query("UNIT:POW?") == "DBM"
    assert meter.link.query("INIT:CONT?") == "OFF"
    assert meter.read_dbm() == -23.45
    assert meter.read_power() == pytest.approx(1e-3 * 10 ** (-2.345), rel=1e-12)
    sent = [text for way, text in meter.link.transcript if way == ">"]
    # every command and query is followed by a look at the error queue
    for k, text in enumerate(sent):
        if text not in ("SYST:ERR?", "*RST", "*OPC?", "*IDN?", "SENS:FREQ?", "UNIT:POW?",
                        "INIT:CONT?"):
            assert sent[k + 1] == "SYST:ERR?", (text, sent)
    assert sent[-4:] == ["INIT", "SYST:ERR?", "FETC?", "SYST:ERR?"]
    meter.close()


def test_a_meter_that_ignores_the_unit_it_is_told_is_refused(rm: pyvisa.ResourceManager) -> None:
    # the meter takes UNIT:POW DBM without an error and reads on in W: its 1E-05 (W) would be
    # taken for -0.00001 dBm, 20 dB from the -20 dBm it measures
    meter = PowerMeter.open("TCPIP::watts.example::5025::SOCKET", rm=rm, timeout_s=0.5)
    with pytest.raises(InstrumentError) as info:
        meter.setup(3.0e8)
    message = str(info.value)
    assert "\n" not in message
    assert "N1913A,MY00000044" in message and "reports unit 'W'" in message
    assert "UNIT:POW DBM" in message
    sent = [text for way, text in meter.link.transcript if way == ">"]
    assert "FETC?" not in sent and "INIT" not in sent
    meter.close()


def test_meter_wrong_identity(rm: pyvisa.ResourceManager) -> None:
    with pytest.raises(InstrumentError, match=r"\*IDN\? answered 'Rohde&Schwarz,NRP2"):
        PowerMeter.open("TCPIP::other.example::5025::SOCKET", rm=rm, timeout_s=0.5)


def test_meter_error_queue_entry_stops(rm: pyvisa.ResourceManager) -> None:
    meter = PowerMeter.open("TCPIP::nounit.example::5025::SOCKET", rm=rm, timeout_s=0.5)
    with pytest.raises(InstrumentError,
                       match=r"reports error -113,\"Undefined header\" after 'UNIT:POW DBM'"):
        meter.setup(3.0e8)


def test_motion_move_and_readback(rm: pyvisa.ResourceManager) -> None:
    esp = MotionController.open("TCPIP::esp.example::5001::SOCKET", rm=rm, timeout_s=0.5)
    esp.setup((1, 2), math.radians(7.5))
    assert esp.link.query("1VA?") == "7.500000"
    got = esp.move({1: math.radians(12.25), 2: math.radians(-3.5)}, tolerance=1e-7,
                   timeout_s=1.0)
    assert math.degrees(got[1]) == pytest.approx(12.25, abs=1e-9)
    assert math.degrees(got[2]) == pytest.approx(-3.5, abs=1e-9)
    sent = [text for way, text in esp.link.transcript if way == ">"]
    assert "1PA12.250000" in sent and "2PA-3.500000" in sent
    for k, text in enumerate(sent):
        if text not in ("VE?", "TE?", "1VA?"):
            assert sent[k + 1] == "TE?", (text, sent)
    esp.close()


def test_motion_unknown_command_reported(rm: pyvisa.ResourceManager) -> None:
    esp = MotionController.open("TCPIP::esp.example::5001::SOCKET", rm=rm, timeout_s=0.5)
    with pytest.raises(InstrumentError, match=r"error 6 \(command does not exist\) after '3MO'"):
        esp.setup((3,), 0.1)


def test_motion_that_never_finishes_is_stopped(rm: pyvisa.ResourceManager) -> None:
    esp = MotionController.open("TCPIP::stuck.example::5001::SOCKET", rm=rm, timeout_s=0.5)
    with pytest.raises(InstrumentError, match=r"axis 2 did not reach its target within 0\.2 s"):
        esp.move({1: math.radians(12.5), 2: math.radians(40.0)}, tolerance=1e-6, timeout_s=0.2)
    sent = [text for way, text in esp.link.transcript if way == ">"]
    assert sent[-2:] == ["1ST", "2ST"]


def test_motion_ending_off_target(rm: pyvisa.ResourceManager) -> None:
    esp = MotionController.open("TCPIP::stuck.example::5001::SOCKET", rm=rm, timeout_s=0.5)
    # axis 1 reports done at 12.5 deg whatever it was told
    with pytest.raises(InstrumentError, match=r"axis 1 stopped at 12\.5000 deg, target 30\.0000"):
        esp.move({1: math.radians(30.0)}, tolerance=math.radians(0.01), timeout_s=0.5)


def test_wrong_controller(rm: pyvisa.ResourceManager) -> None:
    with pytest.raises(InstrumentError, match="expected a Newport ESP301"):
        MotionController.open("TCPIP::esp300.example::5001::SOCKET", rm=rm, timeout_s=0.5)


def test_a_position_read_back_as_nan_is_refused_and_the_axes_stopped(rm: pyvisa.ResourceManager) -> None:
    # abs(nan - target) > tolerance is False: a NaN read-back would pass as on target
    esp = MotionController.open("TCPIP::nan.example::5001::SOCKET", rm=rm, timeout_s=0.5)
    with pytest.raises(InstrumentError, match=r"1TP\? answered 'nan', not a position"):
        esp.move({1: math.radians(10.0)}, tolerance=math.radians(0.01), timeout_s=0.5)
    sent = [text for way, text in esp.link.transcript if way == ">"]
    assert sent[-1] == "1ST"


def test_a_reading_no_sensor_can_give_is_refused(rm: pyvisa.ResourceManager) -> None:
    # +250 dBm is finite and below SCPI's 9.91E37; as a power it would be 1e22 W
    meter = PowerMeter.open("TCPIP::overrange.example::5025::SOCKET", rm=rm, timeout_s=0.5)
    with pytest.raises(InstrumentError, match=r"reading out of range \('\+2\.500000000E\+02'"):
        meter.read_power()
