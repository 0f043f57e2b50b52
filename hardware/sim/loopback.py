"""A line-based instrument server on a loopback TCP port, for the simulated instruments.

Each server listens on 127.0.0.1 only (an ephemeral port unless one is given), accepts any
number of connections, splits what arrives into lines (CR, LF or CR LF end a line), hands each
line to a handler and sends back the handler's answer followed by the dialect's terminator
(no answer for commands, or for a simulated silent instrument). Every loop polls a stop flag at
least every ``poll_s`` seconds, so :meth:`LineServer.stop` returns within a bounded time, and
every socket operation has a timeout.
"""

from __future__ import annotations

import socket
import threading
from collections.abc import Callable

HOST = "127.0.0.1"
MAX_LINE = 65536


class LineServer:
    """Serve ``handler(line) -> answer | None`` on ``TCPIP::127.0.0.1::PORT::SOCKET``.

    Parameters
    ----------
    handler : called with each received line (terminator removed), serialised by a lock.
    name : thread name prefix, for debugging.
    terminator : appended to each answer ("\\n" for SCPI, "\\r\\n" for the ESP301).
    port : fixed port, or 0 for an ephemeral one.
    poll_s : longest time a loop waits before checking the stop flag (s).
    """

    def __init__(self, handler: Callable[[str], str | None], *, name: str,
                 terminator: str = "\n", port: int = 0, poll_s: float = 0.05) -> None:
        self.handler = handler
        self.name = name
        self.terminator = terminator.encode()
        self.poll_s = poll_s
        self._want_port = port
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._threads: list[threading.Thread] = []
        self._listener: socket.socket | None = None
        self.port = 0

    @property
    def resource(self) -> str:
        """The VISA resource name of this server."""
        return f"TCPIP::{HOST}::{self.port}::SOCKET"

    def start(self) -> LineServer:
        """Bind, listen and start accepting in a thread; return self."""
        listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind((HOST, self._want_port))
        listener.listen(8)
        listener.settimeout(self.poll_s)
        self._listener = listener
        self.port = listener.getsockname()[1]
        self._spawn(self._accept_loop, "accept")
        return self

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop accepting, close every connection and join the threads (bounded wait)."""
        self._stop.set()
        for thread in list(self._threads):
            thread.join(timeout_s)
        if self._listener is not None:
            self._listener.close()
            self._listener = None

    def _spawn(self, target: Callable[..., None], what: str, *args: object) -> None:
        thread = threading.Thread(target=target, args=args, name=f"{self.name}-{what}",
                                  daemon=True)
        self._threads.append(thread)
        thread.start()

    def _accept_loop(self) -> None:
        assert self._listener is not None
        while not self._stop.is_set():
            try:
                conn, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.settimeout(self.poll_s)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._spawn(self._serve, "conn", conn)

    def _serve(self, conn: socket.socket) -> None:
        buffer = b""
        with conn:
            while not self._stop.is_set():
                try:
                    chunk = conn.recv(4096)
                except TimeoutError:
                    continue
                except OSError:
                    return
                if not chunk:
                    return
                buffer += chunk
                lines, buffer = _split_lines(buffer)
                if len(buffer) > MAX_LINE:
                    return
                for line in lines:
                    with self._lock:
                        answer = self.handler(line)
                    if answer is None:
                        continue
                    try:
                        conn.sendall(answer.encode() + self.terminator)
                    except OSError:
                        return


def _split_lines(buffer: bytes) -> tuple[list[str], bytes]:
    """Complete lines of ``buffer`` (any of CR, LF, CR LF ends one; empty lines dropped)."""
    text = buffer.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    *complete, rest = text.split(b"\n")
    lines = [c.decode("ascii", errors="replace").strip() for c in complete]
    return [line for line in lines if line], rest
