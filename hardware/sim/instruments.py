"""Protocol models of the simulated instruments: an N1913A power meter and an ESP301 controller.

Each model turns one received line into an answer (or none) the way the real instrument's
dialect does, including its error queue, and knows nothing about sockets (see
:mod:`hardware.sim.loopback`) or about the field it measures (see :mod:`hardware.sim.rig`).
Faults for tests: a wrong identity, an error pushed into the meter's queue at a given reading,
a meter that ignores ``UNIT:POW``, a move that stops short of its target.
"""

from __future__ import annotations

import math
import re
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

NO_ERROR = '+0,"No error"'
METER_IDN = "Keysight Technologies,N1913A,MY53100001,A2.01.08"
ESP_VERSION = "ESP301 Version 3.0.2 6/7/2018"
_SUFFIX = {"HZ": 1.0, "KHZ": 1e3, "MHZ": 1e6, "GHZ": 1e9}
_ESP = re.compile(r"^(\d?)([A-Z]{2})(\?)?\s*(.*)$")


def scpi_is(header: str, pattern: str) -> bool:
    """Whether a SCPI header matches a pattern like ``SENSe:FREQuency`` (short or long form).

    A node may carry a numeric suffix (``SENS1``) and the header a leading colon.
    """
    nodes = header.lstrip(":").upper().split(":")
    parts = pattern.split(":")
    if len(nodes) != len(parts):
        return False
    for node, part in zip(nodes, parts, strict=True):
        node = node.rstrip("0123456789") if not part[-1].isdigit() else node
        short = "".join(ch for ch in part if ch.isupper() or ch in "?*")
        if node not in (short, part.upper()):
            return False
    return True


@dataclass
class PowerMeterModel:
    """An N1913A answering SCPI; ``measure()`` gives the power at the sensor now (dBm).

    ``fixed_unit`` ("DBM" or "W"), when set, is a faulty meter's unit whatever it is told:
    it accepts ``UNIT:POW`` without error and keeps answering ``UNIT:POW?`` and ``FETC?`` in it.
    """

    measure: Callable[[], float]
    idn: str = METER_IDN
    error_at_reading: int | None = None
    fixed_unit: str | None = None
    frequency_hz: float = 50e6
    unit: str = "DBM"
    continuous: bool = True
    readings: int = 0
    errors: deque[str] = field(default_factory=deque)
    _value: float | None = None

    def handle(self, line: str) -> str | None:
        """Answer one line (None: a command without an answer)."""
        header, _, arg = line.strip().partition(" ")
        arg = arg.strip()
        if header == "*IDN?":
            return self.idn
        if header == "*OPC?":
            return "1"
        if header == "*RST":
            self.frequency_hz, self.unit, self.continuous, self._value = 50e6, "DBM", True, None
            return None
        if header == "*CLS":
            self.errors.clear()
            return None
        if scpi_is(header, "SYSTem:ERRor?"):
            return self.errors.popleft() if self.errors else NO_ERROR
        if scpi_is(header, "SENSe:FREQuency"):
            self._set_frequency(arg)
        elif scpi_is(header, "SENSe:FREQuency?"):
            return f"{self.frequency_hz:+.6E}"
        elif scpi_is(header, "UNIT:POWer"):
            if arg.upper() in ("DBM", "W"):
                self.unit = arg.upper()
            else:
                self.errors.append('-224,"Illegal parameter value"')
        elif scpi_is(header, "UNIT:POWer?"):
            return self.fixed_unit or self.unit
        elif scpi_is(header, "INITiate:CONTinuous"):
            self.continuous = arg.upper() in ("ON", "1")
        elif scpi_is(header, "INITiate") or scpi_is(header, "INITiate:IMMediate"):
            self._trigger()
        elif scpi_is(header, "FETCh?"):
            return self._fetch()
        elif scpi_is(header, "READ?"):
            self._trigger()
            return self._fetch()
        else:
            self.errors.append('-113,"Undefined header"')
        return None

    def _set_frequency(self, arg: str) -> None:
        match = re.fullmatch(r"([-+0-9.Ee]+)\s*([A-Za-z]*)", arg)
        try:
            value = float(match.group(1)) * _SUFFIX[(match.group(2) or "HZ").upper()]
        except (AttributeError, KeyError, ValueError):
            self.errors.append('-224,"Illegal parameter value"')
            return
        if not 1e3 <= value <= 1e12:
            self.errors.append('-222,"Data out of range"')
            return
        self.frequency_hz = value

    def _trigger(self) -> None:
        self.readings += 1
        self._value = self.measure()
        if self.error_at_reading is not None and self.readings == self.error_at_reading:
            self.errors.append('-241,"Hardware missing;sensor disconnected"')

    def _fetch(self) -> str:
        if self._value is None:
            self.errors.append('-230,"Data corrupt or stale"')
            return "+9.91E+37"
        if (self.fixed_unit or self.unit) == "W":
            return f"{1e-3 * 10.0 ** (self._value / 10.0):+.9E}"
        return f"{self._value:+.9E}"


@dataclass
class Axis:
    """One simulated rotary axis: a straight move from ``start`` to ``target`` (deg).

    At rest (``duration`` 0 or elapsed) the axis is at ``target``.
    """

    start: float = 0.0
    target: float = 0.0
    t0: float = 0.0
    duration: float = 0.0
    velocity: float = 10.0
    motor_on: bool = False
    low: float = -180.0
    high: float = 180.0

    def at(self, now: float) -> float:
        """Position (deg) at time ``now`` (s, monotonic)."""
        if self.duration <= 0.0 or now >= self.t0 + self.duration:
            return self.target
        return self.start + (self.target - self.start) * (now - self.t0) / self.duration

    def moving(self, now: float) -> bool:
        return self.duration > 0.0 and now < self.t0 + self.duration


@dataclass
class ESP301Model:
    """An ESP301 answering its command set; axes move at their velocity times ``time_scale``.

    ``max_speed`` (deg/s) caps the velocity a client may set; ``stall_at_move`` makes that
    move (counting from 1) stop halfway without an error; ``clock`` gives monotonic seconds.
    """

    axes: dict[int, Axis]
    time_scale: float = 1.0
    max_speed: float | None = None
    stall_at_move: int | None = None
    version: str = ESP_VERSION
    clock: Callable[[], float] = time.monotonic
    moves: int = 0
    errors: deque[int] = field(default_factory=deque)

    def position(self, axis: int) -> float:
        """Where ``axis`` is now (deg)."""
        return self.axes[axis].at(self.clock())

    def handle(self, line: str) -> str | None:
        """Answer one line (None: a command without an answer)."""
        match = _ESP.match(line.strip().upper())
        if match is None:
            self.errors.append(6)
            return None
        number, cmd, query, arg = match.groups()
        if cmd == "VE" and query:
            return self.version
        if cmd == "TE" and query:
            return str(self.errors.popleft() if self.errors else 0)
        if cmd == "TB" and query:
            code = self.errors.popleft() if self.errors else 0
            return f"{code}, 0, {'NO ERROR DETECTED' if code == 0 else 'ERROR'}"
        if not number:
            self.errors.append(37 if cmd in ("PA", "TP", "MD", "MO", "MF", "VA", "ST", "OR")
                               else 6)
            return None
        axis_no = int(number)
        if axis_no not in self.axes:
            self.errors.append(9)
            return None
        return self._axis_command(axis_no, cmd, bool(query), arg)

    def _axis_command(self, n: int, cmd: str, query: bool, arg: str) -> str | None:
        axis = self.axes[n]
        now = self.clock()
        if query:
            answers = {"TP": lambda: f"{axis.at(now):.6f}", "MD": lambda: "0" if axis.moving(now)
                       else "1", "PA": lambda: f"{axis.target:.6f}",
                       "VA": lambda: f"{axis.velocity:.6f}", "MO": lambda: "1" if axis.motor_on
                       else "0"}
            if cmd not in answers:
                self.errors.append(6)
                return None
            return answers[cmd]()
        if cmd == "MO":
            axis.motor_on = True
        elif cmd == "MF":
            self._halt(axis, now)
            axis.motor_on = False
        elif cmd == "ST":
            self._halt(axis, now)
        elif cmd == "VA":
            value = _number(arg)
            if value is None:
                self.errors.append(38)
            elif value <= 0 or (self.max_speed is not None and value > self.max_speed):
                self.errors.append(100 * n + 10)
            else:
                axis.velocity = value
        elif cmd in ("PA", "OR"):
            target = 0.0 if cmd == "OR" else _number(arg)
            if target is None:
                self.errors.append(38)
            elif not axis.motor_on:
                self.errors.append(100 * n + 13)
            elif target > axis.high:
                self.errors.append(100 * n + 6)
            elif target < axis.low:
                self.errors.append(100 * n + 7)
            else:
                self._start_move(axis, target, now)
        else:
            self.errors.append(6)
        return None

    def _start_move(self, axis: Axis, target: float, now: float) -> None:
        self.moves += 1
        here = axis.at(now)
        if self.stall_at_move is not None and self.moves == self.stall_at_move:
            target = here + 0.5 * (target - here)
        axis.start, axis.target, axis.t0 = here, target, now
        axis.duration = abs(target - here) / axis.velocity * self.time_scale

    def _halt(self, axis: Axis, now: float) -> None:
        here = axis.at(now)
        axis.start = axis.target = here
        axis.duration = 0.0


def _number(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None
