"""One instrument connection through PyVISA: bounded reads, one-line errors, a transcript.

The default backend is pyvisa-py (``@py``), which reaches ``TCPIP::HOST::PORT::SOCKET``
resources over plain TCP; tests may pass a pyvisa-sim resource manager instead. Every read
has a timeout; a read that times out leaves the connection in an unknown state (a late answer
could be taken for the next one), so the link refuses further use until it is reopened.
"""

from __future__ import annotations

import socket
import threading
import time
from collections import deque

import pyvisa
import pyvisa.constants
import pyvisa.errors

from raysim.errors import InstrumentError

#: the longest answer line any instrument of the rig gives is tens of bytes (an ``*IDN?``)
MAX_ANSWER_BYTES = 4096
ANSWER_CHUNK = 256  # bytes read at most per call while looking for the line's end
_rm_lock = threading.Lock()
_default_rm: pyvisa.ResourceManager | None = None


def resource_manager() -> pyvisa.ResourceManager:
    """The shared pyvisa-py resource manager (``@py``), created on first use."""
    global _default_rm
    with _rm_lock:
        if _default_rm is None:
            _default_rm = pyvisa.ResourceManager("@py")
        return _default_rm


class VisaLink:
    """A message-based connection to one instrument.

    Parameters
    ----------
    resource : VISA resource name, e.g. ``TCPIP::127.0.0.1::5025::SOCKET``.
    name : what the instrument is, for messages ("power meter").
    timeout_s : limit on every read (s).
    read_termination, write_termination : line terminators of the dialect.
    rm : resource manager; the shared ``@py`` one by default.
    transcript : keep the last this many (direction, text) pairs for inspection.
    """

    def __init__(self, resource: str, *, name: str, timeout_s: float,
                 read_termination: str = "\n", write_termination: str = "\n",
                 rm: pyvisa.ResourceManager | None = None, transcript: int = 256) -> None:
        self.resource = resource
        self.name = name
        self.timeout_s = timeout_s
        self.transcript: deque[tuple[str, str]] = deque(maxlen=transcript)
        self._broken: str | None = None
        self._rm = rm
        self._terminations = (read_termination, write_termination)
        host = tcpip_host(resource) if rm is None else None  # the socket backend resolves names
        if host is not None:
            try:
                socket.getaddrinfo(host, None)
            except (socket.gaierror, UnicodeError) as exc:
                raise InstrumentError(f"{name} at {resource} is unreachable: unknown host "
                                      f"{host!r} ({getattr(exc, 'strerror', None) or exc})") from None
        ms = max(1, round(timeout_s * 1000))
        try:  # the connection and every read are bounded by timeout_s
            self._inst = (rm or resource_manager()).open_resource(
                resource, read_termination=read_termination,
                write_termination=write_termination, timeout=ms, open_timeout=ms)
        except Exception as exc:  # pyvisa-py raises bare Exception for a failed connect
            raise self._error("cannot be opened", exc) from None
        _no_delay(self._inst)

    def write(self, command: str) -> None:
        """Send one command (no answer expected)."""
        self._usable()
        self.transcript.append((">", command))
        try:
            self._inst.write(command)
        except (pyvisa.errors.Error, OSError) as exc:
            self._broken = "write failed"
            raise self._error(f"did not take '{command}'", exc) from exc

    def query(self, command: str) -> str:
        """Send one query and return its answer, stripped; raise if none comes in time."""
        self.write(command)
        try:
            answer = self._read_line(command).strip()
        except pyvisa.errors.VisaIOError as exc:
            self._broken = "a read timed out"
            if exc.error_code == pyvisa.constants.StatusCode.error_timeout:
                if _peer_closed(self._inst):  # pyvisa-py reads an end of stream as silence
                    self._broken = "it closed the connection"
                    raise InstrumentError(f"{self.name} at {self.resource} closed the connection: "
                                          f"no answer to '{command}'") from exc
                raise InstrumentError(f"{self.name} at {self.resource} is silent: no answer to "
                                      f"'{command}' within {self.timeout_s:g} s") from exc
            raise self._error(f"gave no answer to '{command}'", exc) from exc
        except UnicodeDecodeError:
            self._broken = "a read failed"
            raise InstrumentError(f"{self.name} at {self.resource} answered '{command}' with bytes "
                                  "that are not ASCII text") from None
        except (pyvisa.errors.Error, OSError) as exc:
            self._broken = "a read failed"
            raise self._error(f"gave no answer to '{command}'", exc) from exc
        self.transcript.append(("<", answer))
        return answer

    def _read_line(self, command: str) -> str:
        """One answer line, bounded in length (:data:`MAX_ANSWER_BYTES`) and in time (the
        read timeout, for the whole line): a reader that waits for the terminator alone would
        take an endless stream without one, chunk by chunk, until memory ran out."""
        end = self._terminations[0].encode("ascii")
        deadline = time.monotonic() + self.timeout_s
        line = b""
        while not line.endswith(end):
            line += self._inst.read_bytes(ANSWER_CHUNK, break_on_termchar=True)
            if len(line) > MAX_ANSWER_BYTES or (time.monotonic() > deadline and not line.endswith(end)):
                self._broken = "an answer without end"
                what = (f"more than {MAX_ANSWER_BYTES} bytes" if len(line) > MAX_ANSWER_BYTES
                        else f"no line end within {self.timeout_s:g} s")
                raise InstrumentError(f"{self.name} at {self.resource} answered '{command}' with "
                                      f"{what}: not one of its answers")
        return line[: len(line) - len(end)].decode("ascii")

    def reopened(self) -> VisaLink:
        """A new connection to the same instrument, with the same settings (to stop the axes
        when this one can no longer be used)."""
        read, write = self._terminations
        return VisaLink(self.resource, name=self.name, timeout_s=self.timeout_s,
                        read_termination=read, write_termination=write, rm=self._rm)

    def close(self) -> None:
        """Close the connection (idempotent, never raises)."""
        try:
            self._inst.close()
        except Exception:  # closing a dead link must not mask the first error
            pass

    def _usable(self) -> None:
        if self._broken is not None:
            raise InstrumentError(f"{self.name} at {self.resource}: link unusable after "
                                  f"{self._broken}; reconnect")

    def _error(self, what: str, exc: BaseException) -> InstrumentError:
        if isinstance(exc, ConnectionRefusedError | ConnectionResetError | BrokenPipeError):
            return InstrumentError(f"{self.name} at {self.resource} is unreachable "
                                   f"({exc.strerror or exc.__class__.__name__})")
        if isinstance(exc, OSError):
            return InstrumentError(f"{self.name} at {self.resource} is unreachable ({exc})")
        detail = getattr(exc, "description", None) or str(exc) or exc.__class__.__name__
        return InstrumentError(f"{self.name} at {self.resource} {what} ({' '.join(detail.split())}; "
                               f"within {self.timeout_s:g} s)")


def tcpip_host(resource: str) -> str | None:
    """The host of a ``TCPIP[n]::HOST::...`` VISA resource name, or None for other kinds."""
    parts = resource.split("::")
    if len(parts) >= 2 and parts[0].upper().startswith("TCPIP"):
        return parts[1] or None
    return None


def _no_delay(inst: pyvisa.resources.Resource) -> None:
    """Send each command at once (TCP_NODELAY) on a TCP socket resource.

    Without it, a command with no answer followed by the error-queue query waits for the
    instrument's delayed ACK (Nagle's algorithm), about 40 ms per command on Linux. pyvisa-py
    does not accept ``VI_ATTR_TCPIP_NODELAY`` on SOCKET sessions, so the option goes on its
    socket directly; other backends take the attribute or keep their default.
    """
    try:
        inst.set_visa_attribute(pyvisa.constants.VI_ATTR_TCPIP_NODELAY, pyvisa.constants.VI_TRUE)
        return
    except Exception:  # pyvisa-py raises its own UnknownAttribute here
        pass
    sock = _socket_of(inst)
    if sock is not None:
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        except OSError:
            pass


def _socket_of(inst: pyvisa.resources.Resource) -> socket.socket | None:
    """The TCP socket under a pyvisa-py SOCKET session (None for other backends)."""
    session = getattr(getattr(inst, "visalib", None), "sessions", {}).get(
        getattr(inst, "session", None))
    sock = getattr(session, "interface", None)
    return sock if isinstance(sock, socket.socket) else None


def _peer_closed(inst: pyvisa.resources.Resource) -> bool:
    """Whether the instrument closed its end of the connection (its process died, it was
    switched off cleanly): the socket is at end of stream. Asked after a read timed out,
    since pyvisa-py waits out the timeout on a closed socket as on a silent one; a peek
    that does not block and takes nothing. False when it cannot tell (another backend)."""
    sock = _socket_of(inst)
    if sock is None:
        return False
    try:
        return sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) == b""
    except OSError:  # BlockingIOError: open with nothing to read; a reset: not a clean close
        return False


class CheckedInstrument:
    """An instrument on one :class:`VisaLink` whose every command and query is followed by a
    read of its error queue. Drivers supply ``identify()`` and ``check_errors(after)``."""

    def __init__(self, link: VisaLink) -> None:
        self.link = link

    @classmethod
    def _connect(cls, link: VisaLink, **kwargs):
        """Wrap ``link``, check the instrument's identity, and close the link if that fails."""
        instrument = cls(link, **kwargs)
        try:
            instrument.identify()
        except BaseException:
            instrument.close()
            raise
        return instrument

    def identify(self) -> str:  # pragma: no cover - every driver overrides it
        raise NotImplementedError

    def check_errors(self, after: str = "") -> None:  # pragma: no cover - every driver overrides it
        raise NotImplementedError

    def command(self, command: str) -> None:
        """Send a command, then check the error queue."""
        self.link.write(command)
        self.check_errors(after=command)

    def query(self, command: str) -> str:
        """Send a query, read its answer, then check the error queue."""
        answer = self.link.query(command)
        self.check_errors(after=command)
        return answer

    def close(self) -> None:
        """Close the link (never raises)."""
        self.link.close()
