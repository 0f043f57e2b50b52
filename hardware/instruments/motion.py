"""Driver for a Newport ESP301 motion controller (two rotary axes, positions in degrees).

Commands used (n = axis number): ``VE?`` (identity), ``nMO`` (motor on), ``nVA<v>``
(velocity), ``nPA<x>`` (absolute move), ``nMD?`` (motion done: 1 done, 0 moving), ``nTP?``
(actual position), ``nOR`` (search home), ``nST`` (stop) and ``TE?`` (oldest error code, 0 when
none; axis errors read 100 n + code). After every command and query ``TE?`` is read until it
answers 0. Commands end with CR, answers with CR LF. Angles cross this boundary in degrees and
leave it in radians. Every wait has a deadline; a move that has not finished by then, or that
ends away from its target, is stopped and reported.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping

import pyvisa

from hardware.instruments.visa import CheckedInstrument, VisaLink
from raysim.errors import InstrumentError

MAX_QUEUE = 10
GENERAL_ERRORS = {
    1: "PCI communication time-out", 4: "emergency stop activated", 6: "command does not exist",
    7: "parameter out of range", 8: "cable interlock error", 9: "axis number out of range",
    13: "group number missing", 20: "data acquisition is busy", 37: "axis number missing",
    38: "command parameter missing",
}
AXIS_ERRORS = {
    0: "motor type not defined", 1: "parameter out of range", 2: "amplifier fault detected",
    3: "following error threshold exceeded", 4: "positive hardware limit detected",
    5: "negative hardware limit detected", 6: "positive software limit detected",
    7: "negative software limit detected", 8: "motor / stage not connected",
    9: "feedback signal fault detected", 10: "maximum velocity exceeded",
    11: "maximum acceleration exceeded", 13: "motor not enabled",
}


def describe_error(code: int) -> str:
    """Text for an ESP301 error code (axis errors are 100 * axis + code)."""
    if code >= 100:
        axis, sub = divmod(code, 100)
        return f"axis {axis}: {AXIS_ERRORS.get(sub, f'error {sub}')}"
    return GENERAL_ERRORS.get(code, f"error {code}")


class MotionController(CheckedInstrument):
    """An ESP301 on one VISA link (terminators CR out, CR LF in)."""

    def __init__(self, link: VisaLink, poll_s: float = 0.002) -> None:
        super().__init__(link)
        self.poll_s = poll_s
        self.version = ""

    @classmethod
    def open(cls, resource: str, *, timeout_s: float = 2.0,
             rm: pyvisa.ResourceManager | None = None) -> MotionController:
        """Connect to the controller at ``resource`` and check it is an ESP301 (``VE?``)."""
        link = VisaLink(resource, name="motion controller", timeout_s=timeout_s, rm=rm,
                        read_termination="\r\n", write_termination="\r")
        return cls._connect(link)

    def identify(self) -> str:
        """Ask ``VE?``; raise unless the answer names an ESP301."""
        version = self.link.query("VE?")
        if "ESP301" not in version.upper():
            raise InstrumentError(f"motion controller at {self.link.resource}: VE? answered "
                                  f"'{version}', expected a Newport ESP301")
        self.version = version
        return version

    def check_errors(self, after: str = "") -> None:
        """Read ``TE?`` until 0; raise :class:`InstrumentError` naming the first error."""
        codes: list[int] = []
        for _ in range(MAX_QUEUE):
            answer = self.link.query("TE?")
            try:
                code = int(answer)
            except ValueError as exc:
                raise InstrumentError(f"motion controller at {self.link.resource}: TE? answered "
                                      f"'{answer}', not an error code") from exc
            if code == 0:
                break
            codes.append(code)
        if codes:
            context = f" after '{after}'" if after else ""
            raise InstrumentError(f"motion controller at {self.link.resource} reports error "
                                  f"{codes[0]} ({describe_error(codes[0])}){context}")

    def setup(self, axes: tuple[int, ...], speed: float) -> None:
        """Switch the axes' motors on and set their velocity (rad/s)."""
        for axis in axes:
            self.command(f"{axis}MO")
            self.command(f"{axis}VA{math.degrees(speed):.6f}")

    def position(self, axis: int) -> float:
        """Actual position of ``axis`` (rad)."""
        answer = self.query(f"{axis}TP?")
        try:
            value = float(answer)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):  # a NaN would pass any tolerance test
            raise InstrumentError(f"motion controller at {self.link.resource}: {axis}TP? "
                                  f"answered '{answer}', not a position")
        return math.radians(value)

    def done(self, axis: int) -> bool:
        """Whether ``axis`` has finished its motion (``nMD?``)."""
        answer = self.query(f"{axis}MD?")
        if answer not in ("0", "1"):
            raise InstrumentError(f"motion controller at {self.link.resource}: {axis}MD? "
                                  f"answered '{answer}', expected 0 or 1")
        return answer == "1"

    def move(self, targets: Mapping[int, float], *, tolerance: float,
             timeout_s: float) -> dict[int, float]:
        """Move axes to absolute targets (rad) together; return the read-back positions (rad).

        Waits at most ``timeout_s`` (s); raises :class:`InstrumentError` (after stopping the
        axes) if a move does not finish in time or ends more than ``tolerance`` (rad) away.
        """
        for axis, target in targets.items():
            self.command(f"{axis}PA{math.degrees(target):.6f}")
        deadline = time.monotonic() + timeout_s
        pending = set(targets)
        while pending:
            pending = {axis for axis in pending if not self.done(axis)}
            if not pending:
                break
            if time.monotonic() > deadline:
                self.stop(targets)
                raise InstrumentError(
                    f"motion controller at {self.link.resource}: axis {min(pending)} did not "
                    f"reach its target within {timeout_s:g} s")
            time.sleep(self.poll_s)
        try:
            readback = {axis: self.position(axis) for axis in targets}
        except InstrumentError:
            self.stop(targets)
            raise
        for axis, target in targets.items():
            if abs(readback[axis] - target) > tolerance:
                self.stop(targets)
                raise InstrumentError(
                    f"motion controller at {self.link.resource}: axis {axis} stopped at "
                    f"{math.degrees(readback[axis]):.4f} deg, target "
                    f"{math.degrees(target):.4f} deg (tolerance "
                    f"{math.degrees(tolerance):g} deg)")
        return readback

    def home(self, axes: tuple[int, ...], timeout_s: float) -> None:
        """Search the home switch of each axis (``nOR``) and wait for it (s)."""
        for axis in axes:
            self.command(f"{axis}OR")
        deadline = time.monotonic() + timeout_s
        while not all(self.done(axis) for axis in axes):
            if time.monotonic() > deadline:
                self.stop(axes)
                raise InstrumentError(f"motion controller at {self.link.resource}: homing did "
                                      f"not finish within {timeout_s:g} s")
            time.sleep(self.poll_s)

    def stop(self, axes) -> None:
        """Stop the axes, best effort (used while already handling a failure; never raises).
        When this link can no longer be used (a read timed out, the controller closed it),
        the stop goes through a new connection: a move under way must not run on."""
        try:
            for axis in axes:
                self.link.write(f"{axis}ST")
            return
        except InstrumentError:
            pass
        try:
            fresh = self.link.reopened()
        except Exception:  # unreachable: nothing more can be done from here
            return
        try:
            for axis in axes:
                fresh.write(f"{axis}ST")
        except Exception:
            pass
        finally:
            fresh.close()
