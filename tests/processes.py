"""Process helpers of the tests that start real Dask schedulers and workers on loopback."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def kill_group(proc: subprocess.Popen) -> None:
    """Stop a process started in its own session, and everything it started."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(timeout=15)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=15)
    with contextlib.suppress(ProcessLookupError):  # children that outlived their parent
        os.killpg(proc.pid, signal.SIGKILL)


def worker_processes(nanny_pid: int) -> list[int]:
    """The worker processes a `dask worker` (nanny) process spawned (not its resource tracker)."""
    out: list[int] = []
    for task in Path(f"/proc/{nanny_pid}/task").iterdir():
        for child in (task / "children").read_text().split():
            with contextlib.suppress(OSError):
                cmdline = Path(f"/proc/{child}/cmdline").read_bytes()
                if b"spawn_main" in cmdline:
                    out.append(int(child))
    return out


def wait_until(predicate, timeout: float, what: str) -> None:
    """Poll ``predicate`` every 50 ms until it holds, or fail naming ``what``."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(0.05)


def listening(port: int) -> bool:
    """Whether something accepts connections on 127.0.0.1:``port``."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.settimeout(0.2)
        return s.connect_ex(("127.0.0.1", port)) == 0


@contextlib.contextmanager
def dask_processes(n_workers: int, worker_timeout: float = 120.0) -> Iterator[tuple[str, int]]:
    """A separately started ``dask scheduler`` and one ``dask worker`` nanny with ``n_workers``
    processes (one thread each) on loopback; yields (scheduler address, nanny pid) once every
    worker process is up, and stops them all on exit."""
    from tests.cli import cli_env

    port = free_port()
    common = dict(env=cli_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                  start_new_session=True)
    scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host",
                                  "127.0.0.1", "--port", str(port), "--no-dashboard"], **common)
    nanny = None
    try:
        wait_until(lambda: listening(port), 60, "the scheduler to listen")
        address = f"tcp://127.0.0.1:{port}"
        nanny = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                                  "--host", "127.0.0.1", "--nworkers", str(n_workers),
                                  "--nthreads", "1", "--no-dashboard"], **common)
        wait_until(lambda: len(worker_processes(nanny.pid)) == n_workers, worker_timeout,
                   f"{n_workers} worker processes")
        yield address, nanny.pid
    finally:
        for proc in (nanny, scheduler):
            if proc is not None:
                kill_group(proc)
