"""Protocol transcripts of the simulated N1913A and ESP301 (no sockets)."""

from __future__ import annotations

import pytest

from hardware.sim.instruments import NO_ERROR, Axis, ESP301Model, PowerMeterModel, scpi_is


def transcript(model, lines: list[str]) -> list[str | None]:
    return [model.handle(line) for line in lines]


def test_scpi_short_and_long_forms() -> None:
    assert scpi_is("SENS:FREQ", "SENSe:FREQuency")
    assert scpi_is(":sense1:frequency", "SENSe:FREQuency")
    assert scpi_is("SYST:ERR?", "SYSTem:ERRor?")
    assert not scpi_is("SENS:FRE", "SENSe:FREQuency")
    assert not scpi_is("SENS:FREQ?", "SENSe:FREQuency")
    assert not scpi_is("FREQ", "SENSe:FREQuency")


def test_meter_transcript() -> None:
    readings = iter([-21.5, -22.25])
    meter = PowerMeterModel(lambda: next(readings))
    answers = transcript(meter, [
        "*IDN?", "FETC?", "SYST:ERR?", "SYST:ERR?",
        "SENS:FREQ 3.000000E+08", "SENS:FREQ?", "SENS:FREQ 2.5GHZ", "SENSe:FREQuency?",
        "SENS:FREQ 1e15", "SYST:ERR?", "UNIT:POW DBM", "INIT", "FETC?", "FETCh?",
        "UNIT:POW W", "INIT", "FETC?", "BOGUS:CMD", "SYST:ERR?", "SYST:ERR?",
    ])
    assert answers[0].split(",")[1] == "N1913A"
    assert answers[1] == "+9.91E+37"                       # nothing measured yet
    assert answers[2] == '-230,"Data corrupt or stale"'
    assert answers[3] == NO_ERROR
    assert answers[4] is None
    assert float(answers[5]) == 3e8
    assert float(answers[7]) == 2.5e9
    assert answers[9] == '-222,"Data out of range"'
    assert float(answers[12]) == -21.5 and answers[13] == answers[12]
    assert float(answers[16]) == pytest.approx(1e-3 * 10 ** (-2.225), rel=1e-9)
    assert answers[18] == '-113,"Undefined header"'
    assert answers[19] == NO_ERROR
    assert meter.readings == 2


def test_meter_reports_its_unit_and_a_faulty_one_keeps_its_own() -> None:
    meter = PowerMeterModel(lambda: -20.0)
    assert transcript(meter, ["UNIT:POW?", "UNIT:POW W", "UNIT:POW?", "*RST", "UNIT:POW?"]
                      )[::2] == ["DBM", "W", "DBM"]
    stuck = PowerMeterModel(lambda: -20.0, fixed_unit="W")
    answers = transcript(stuck, ["UNIT:POW DBM", "SYST:ERR?", "UNIT:POW?", "INIT", "FETC?"])
    assert answers[1] == NO_ERROR and answers[2] == "W"
    assert float(answers[4]) == pytest.approx(1e-5, rel=1e-9)   # -20 dBm, in W


def test_meter_error_at_reading() -> None:
    meter = PowerMeterModel(lambda: -30.0, error_at_reading=2)
    assert transcript(meter, ["INIT", "SYST:ERR?", "INIT", "SYST:ERR?"])[1::2] == [
        NO_ERROR, '-241,"Hardware missing;sensor disconnected"']


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def make_esp(clock: Clock, **kw) -> ESP301Model:
    return ESP301Model({1: Axis(low=-95, high=95), 2: Axis(low=-5, high=185)}, clock=clock, **kw)


def test_esp_move_takes_distance_over_velocity() -> None:
    clock = Clock()
    esp = make_esp(clock)
    assert transcript(esp, ["VE?"])[0].startswith("ESP301")
    assert transcript(esp, ["1MO", "1VA4", "1PA20", "TE?", "1MD?", "1TP?"]) == [
        None, None, None, "0", "0", "0.000000"]
    clock.t += 2.5                                   # 20 deg at 4 deg/s takes 5 s
    assert transcript(esp, ["1MD?", "1TP?"]) == ["0", "10.000000"]
    clock.t += 2.5
    assert transcript(esp, ["1MD?", "1TP?", "1PA?"]) == ["1", "20.000000", "20.000000"]


def test_esp_time_scale_and_stop() -> None:
    clock = Clock()
    esp = make_esp(clock, time_scale=0.1)
    transcript(esp, ["2MO", "2VA10", "2PA100"])       # 10 s of motion, 1 s scaled
    clock.t += 0.5
    assert transcript(esp, ["2TP?", "2ST", "2MD?"]) == ["50.000000", None, "1"]
    clock.t += 5.0
    assert esp.handle("2TP?") == "50.000000"


def test_esp_errors() -> None:
    clock = Clock()
    esp = make_esp(clock)
    answers = transcript(esp, [
        "1PA10", "TE?",            # motor off
        "1MO", "1PA120", "TE?",    # beyond the positive software limit
        "1PA-120", "TE?",          # beyond the negative one
        "4MO", "TE?",              # no such axis
        "1XX", "TE?",              # no such command
        "PA5", "TE?",              # axis number missing
        "1VA", "TE?",              # parameter missing
        "TE?",
    ])
    assert answers[1::2][:1] == ["113"]
    assert [answers[i] for i in (4, 6, 8, 10, 12, 14, 15)] == ["106", "107", "9", "6", "37",
                                                              "38", "0"]
    assert esp.handle("1TP?") == "0.000000"


def test_esp_stall() -> None:
    clock = Clock()
    esp = make_esp(clock, time_scale=0.0, stall_at_move=2)
    assert transcript(esp, ["1MO", "1PA10", "1MD?", "1TP?", "1PA30", "1MD?", "1TP?", "TE?"]) == [
        None, None, "1", "10.000000", None, "1", "20.000000", "0"]
