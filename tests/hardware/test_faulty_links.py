"""Faults only a real connection shows: an answer without end, a controller gone silent.

A small server on a loopback socket plays the instrument (written here from the ESP301's and
the N1913A's command strings, not from the project's simulated instruments); the drivers talk
to it through pyvisa-py, as they talk to a rig.
"""

from __future__ import annotations

import math
import socket
import threading
import time
from collections.abc import Callable, Iterator

import pytest

from hardware.instruments.motion import MotionController
from hardware.instruments.visa import MAX_ANSWER_BYTES, VisaLink
from raysim.errors import InstrumentError


class Server:
    """Accepts connections; ``answer(line)`` gives bytes to send back, None for nothing, or
    ``FLOOD`` for an endless stream without a line end. Every line received is logged per
    connection."""

    FLOOD = object()
    CLOSE = object()

    def __init__(self, answer: Callable[[str], object]) -> None:
        self.answer = answer
        self.received: list[list[str]] = []
        self._sock = socket.socket()
        self._sock.bind(("127.0.0.1", 0))
        self._sock.listen(4)
        self.port = self._sock.getsockname()[1]
        self._stop = threading.Event()
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._sock.accept()
            except OSError:
                return
            log: list[str] = []
            self.received.append(log)
            threading.Thread(target=self._serve, args=(conn, log), daemon=True).start()

    def _serve(self, conn: socket.socket, log: list[str]) -> None:
        buf = b""
        with conn:
            while not self._stop.is_set():
                try:
                    chunk = conn.recv(4096)
                except OSError:
                    return
                if not chunk:
                    return
                buf += chunk
                *lines, buf = buf.replace(b"\r", b"\n").split(b"\n")
                for raw in lines:
                    line = raw.decode().strip()
                    if not line:
                        continue
                    log.append(line)
                    reply = self.answer(line)
                    if reply is Server.CLOSE:
                        return  # the with block closes the connection: the peer reads EOF
                    try:
                        if reply is Server.FLOOD:
                            while not self._stop.is_set():
                                conn.sendall(b"1" * 65536)
                        elif reply is not None:
                            conn.sendall(reply)  # type: ignore[arg-type]
                    except OSError:
                        return

    def close(self) -> None:
        self._stop.set()
        self._sock.close()


@pytest.fixture
def serve() -> Iterator[Callable[[Callable[[str], object]], Server]]:
    servers: list[Server] = []

    def make(answer: Callable[[str], object]) -> Server:
        servers.append(Server(answer))
        return servers[-1]

    yield make
    for server in servers:
        server.close()


def test_an_answer_without_end_is_refused_at_once_not_read_until_memory_runs_out(serve) -> None:
    server = serve(lambda line: Server.FLOOD if line == "FETC?" else b"0\n")
    link = VisaLink(f"TCPIP::127.0.0.1::{server.port}::SOCKET", name="power meter", timeout_s=1.0)
    start = time.monotonic()
    with pytest.raises(InstrumentError, match=f"more than {MAX_ANSWER_BYTES} bytes"):
        link.query("FETC?")
    assert time.monotonic() - start < 1.0
    with pytest.raises(InstrumentError, match="link unusable"):
        link.query("FETC?")
    link.close()


def test_a_meter_that_closed_the_connection_is_not_called_silent(serve) -> None:
    # QA: a meter whose process died mid-scan was reported "silent: no answer within 2 s"
    server = serve(lambda line: Server.CLOSE if line == "FETC?" else None)
    link = VisaLink(f"TCPIP::127.0.0.1::{server.port}::SOCKET", name="power meter", timeout_s=0.3)
    with pytest.raises(InstrumentError) as info:
        link.query("FETC?")
    assert str(info.value) == (f"power meter at TCPIP::127.0.0.1::{server.port}::SOCKET closed "
                               "the connection: no answer to 'FETC?'")
    link.close()
    # one that is connected and says nothing is still silent
    quiet = serve(lambda line: None)
    link = VisaLink(f"TCPIP::127.0.0.1::{quiet.port}::SOCKET", name="power meter", timeout_s=0.3)
    with pytest.raises(InstrumentError, match=r"is silent: no answer to 'FETC\?' within 0\.3 s"):
        link.query("FETC?")
    link.close()


def test_a_controller_gone_silent_mid_move_is_stopped_through_a_new_connection(serve) -> None:
    def esp301(line: str) -> object:
        if line == "VE?":
            return b"ESP301 Version 3.0.2 6/7/2018\r\n"
        if line == "TE?":
            return b"0\r\n"
        if line == "1MD?":
            return None  # silent: the first link times out while the axis moves
        return b"0\r\n" if line.endswith("?") else None

    server = serve(esp301)
    esp = MotionController.open(f"TCPIP::127.0.0.1::{server.port}::SOCKET", timeout_s=0.3)
    with pytest.raises(InstrumentError, match=r"is silent: no answer to '1MD\?'"):
        esp.move({1: math.radians(30.0)}, tolerance=1e-6, timeout_s=5.0)
    esp.stop((1, 2))  # what acquire and park do on any failure
    esp.close()
    # the server logs each line on its own thread: wait for both stops (waiting for the first
    # alone raced the second's arrival on a loaded machine)
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and not any(log[-2:] == ["1ST", "2ST"]
                                                  for log in server.received[1:]):
        time.sleep(0.02)
    first, *later = server.received
    assert "1PA30.000000" in first and "1ST" not in first
    assert any(log[-2:] == ["1ST", "2ST"] for log in later), server.received
