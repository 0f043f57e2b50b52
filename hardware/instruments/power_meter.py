"""Driver for a microwave power meter speaking the Keysight EPM N1913A / N1914A SCPI dialect.

Commands used: ``*IDN?``, ``*RST``, ``*CLS``, ``*OPC?``, ``SENS:FREQ <Hz>``, ``UNIT:POW DBM``,
``UNIT:POW?``, ``INIT:CONT OFF``, ``INIT``, ``FETC?`` and ``SYST:ERR?``. After every command and
query the error queue is read until it answers ``+0,"No error"``; any entry stops the scan with a
one-line :class:`InstrumentError`. The unit is read back after it is set: a meter left in W would
otherwise give readings taken for dBm. Readings cross this boundary in dBm and leave it in W.
"""

from __future__ import annotations

import math

import pyvisa

from hardware.instruments.visa import CheckedInstrument, VisaLink
from raysim.errors import InstrumentError

MODELS = ("N1913A", "N1914A")
MAX_QUEUE = 32          # entries drained from the error queue at most
#: what any power sensor can read (dBm): thermal noise in 1 Hz is -174 dBm, and the N191xA
#: sensors stop near +44 dBm; a reading outside is a fault, never a power (SCPI's 9.91E37
#: "not a number" included), and would otherwise become 0 W or overflow
DBM_RANGE = (-174.0, 60.0)


class PowerMeter(CheckedInstrument):
    """A Keysight N1913A/N1914A (or a compatible meter) on one VISA link.

    Parameters
    ----------
    link : the open connection (line terminator LF).
    """

    def __init__(self, link: VisaLink) -> None:
        super().__init__(link)
        self.idn = ""

    @classmethod
    def open(cls, resource: str, *, timeout_s: float = 2.0,
             rm: pyvisa.ResourceManager | None = None) -> PowerMeter:
        """Connect to the meter at ``resource`` and check it is one (``*IDN?``)."""
        return cls._connect(VisaLink(resource, name="power meter", timeout_s=timeout_s, rm=rm))

    def identify(self) -> str:
        """Ask ``*IDN?``; raise unless the model field names an N1913A or N1914A."""
        idn = self.link.query("*IDN?")
        fields = [f.strip() for f in idn.split(",")]
        if len(fields) < 2 or fields[1].upper() not in MODELS:
            raise InstrumentError(f"power meter at {self.link.resource}: *IDN? answered "
                                  f"'{idn}', expected a Keysight {' or '.join(MODELS)}")
        self.idn = idn
        return idn

    def check_errors(self, after: str = "") -> None:
        """Drain ``SYST:ERR?``; raise :class:`InstrumentError` naming the first entry if any."""
        errors: list[str] = []
        for _ in range(MAX_QUEUE):
            answer = self.link.query("SYST:ERR?")
            code, _, message = answer.partition(",")
            try:
                number = int(code)
            except ValueError as exc:
                raise InstrumentError(f"power meter at {self.link.resource}: SYST:ERR? answered "
                                      f"'{answer}', not an error entry") from exc
            if number == 0:
                break
            errors.append(f"{number},{message.strip()}")
        if errors:
            context = f" after '{after}'" if after else ""
            more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
            raise InstrumentError(f"power meter at {self.link.resource} reports error "
                                  f"{errors[0]}{context}{more}")

    def setup(self, frequency_hz: float) -> None:
        """Reset, clear, set the frequency (Hz, for the sensor's cal factor), dBm, single shot."""
        self.link.write("*RST")
        self.link.query("*OPC?")
        self.link.write("*CLS")
        self.check_errors(after="*RST")
        self.command(f"SENS:FREQ {frequency_hz:.6E}")
        self.command("UNIT:POW DBM")
        self.check_unit("DBM")
        self.command("INIT:CONT OFF")

    def check_unit(self, wanted: str) -> None:
        """Read ``UNIT:POW?`` back; raise :class:`InstrumentError` unless it is ``wanted``.

        An N191x answers ``DBM`` or ``W``. A meter that accepts ``UNIT:POW DBM`` without error
        but keeps reading in W would pass every other check, its readings (e.g. 1E-05 W) then
        taken for dBm: intensities wrong by orders of magnitude, with nothing said.
        """
        answer = self.query("UNIT:POW?")
        unit = answer.strip().strip('"').upper()
        if unit != wanted.upper():
            who = f"power meter '{self.idn}'" if self.idn else "power meter"
            raise InstrumentError(f"{who} at {self.link.resource} reports unit '{answer}' "
                                  f"after 'UNIT:POW {wanted}': it does not read in {wanted}")

    def read_dbm(self) -> float:
        """Trigger one measurement and fetch it (dBm)."""
        self.command("INIT")
        answer = self.query("FETC?")
        try:
            value = float(answer)
        except ValueError as exc:
            raise InstrumentError(f"power meter at {self.link.resource}: FETC? answered "
                                  f"'{answer}', not a number") from exc
        if not math.isfinite(value) or not DBM_RANGE[0] <= value <= DBM_RANGE[1]:
            raise InstrumentError(f"power meter at {self.link.resource}: reading out of range "
                                  f"('{answer}'; a power sensor reads {DBM_RANGE[0]:g} to "
                                  f"{DBM_RANGE[1]:+g} dBm)")
        return value

    def read_power(self) -> float:
        """One reading in W."""
        return 1e-3 * 10.0 ** (self.read_dbm() / 10.0)
