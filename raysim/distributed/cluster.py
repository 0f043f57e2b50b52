"""Reaching a Dask cluster: a running scheduler (with timeouts and one-line errors) or a local one.

:func:`connect` is the one way raysim opens a Dask client: ``scheduler="tcp://host:port"``
connects to a running scheduler within :data:`CONNECT_TIMEOUT_S` and waits up to
:data:`WORKER_WAIT_S` for a first worker; without it a local cluster of worker processes
(one thread each, bound to 127.0.0.1, no dashboard) is started and closed afterwards. Every
failure a user can cause (a malformed address, nothing listening, no worker joining, a local
cluster that cannot start) is a :class:`ClusterError` naming the address, one line.

Devices: with ``device="cuda"`` a local cluster has one worker per visible GPU, and
:func:`worker_device` gives each worker its own: ``cuda:N`` from a trailing number in the
worker's name (a local cluster names its workers 0, 1, ...; ``dask worker --name gpu
--nworkers 2`` gives gpu-0, gpu-1), modulo the GPUs the process sees; a worker started with
``CUDA_VISIBLE_DEVICES=i`` sees one GPU, ``cuda:0``.
"""

from __future__ import annotations

import contextlib
import gc
import logging
import os
import re
import signal
import socket
import sys
import threading
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from raysim.errors import RaysimError

CONNECT_TIMEOUT_S = 20.0
WORKER_WAIT_S = 120.0
#: what a local cluster's processes log to the shared stderr: nothing below CRITICAL. A task's
#: error reaches the client as its exception; what workers log at ERROR is their shutdown
#: (heartbeats to a scheduler that closed while a task ran: pages of tracebacks after an
#: interrupt sent to the client alone)
_WORKER_LOG_LEVEL = logging.CRITICAL
_ADDRESS = re.compile(r"(?:(?P<scheme>tcp|tls|ws|wss|ucx)://)?(?P<host>\[[0-9A-Fa-f:.]+\]|[\w.-]+):(?P<port>\d{1,5})")


class ClusterError(RaysimError, RuntimeError):
    """A Dask cluster cannot be reached or started, or its workers cannot do the work."""


@dataclass(frozen=True)
class Cluster:
    """An open client: ``workers`` at the start, ``address`` of the scheduler (``local``
    for a local cluster)."""

    client: Any
    workers: int
    address: str


def scheduler_address(text: str) -> str:
    """``text`` as a scheduler address (``tcp://host:port``; a bare ``host:port`` gets
    ``tcp://``), or ClusterError. ``inproc://`` addresses (a cluster in this process) pass."""
    text = text.strip()
    if text.startswith("inproc://"):
        return text
    match = _ADDRESS.fullmatch(text)
    if match is None or not 0 < int(match["port"]) < 65536:
        raise ClusterError(f"scheduler address {text!r} is not of the form tcp://HOST:PORT")
    return text if match["scheme"] else f"tcp://{text}"


def usable_cores() -> int:
    """CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - non-Linux
        return os.cpu_count() or 1


def gpu_count() -> int:
    """CUDA devices this process sees (0 without Warp's CUDA driver)."""
    from raysim.optics import runtime

    wp = runtime.init()
    return int(wp.get_cuda_device_count()) if wp.is_cuda_available() else 0


@contextlib.contextmanager
def connect(scheduler: str | None = None, *, workers: int | None = None, threads: int = 1,
            device: str = "cpu", tasks: int | None = None, timeout: float | None = None,
            worker_wait: float | None = None) -> Iterator[Cluster]:
    """A Dask client on ``scheduler`` or on a new local cluster, closed on exit.

    ``workers``: local worker processes (default: one per usable core divided by ``threads``,
    one per GPU for ``cuda``; never more than ``tasks`` when given); ignored with a scheduler.
    ``threads``: ``RAYSIM_THREADS`` of the local workers. ``timeout`` (s, default
    :data:`CONNECT_TIMEOUT_S`): for the scheduler's first answer; ``worker_wait`` (s, default
    :data:`WORKER_WAIT_S`): for its first worker.
    """
    if scheduler:
        timeout = CONNECT_TIMEOUT_S if timeout is None else timeout
        worker_wait = WORKER_WAIT_S if worker_wait is None else worker_wait
        with _remote(scheduler_address(scheduler), timeout, worker_wait) as cluster:
            yield cluster
        return
    with _local(workers, threads, device, tasks) as cluster:
        yield cluster


@contextlib.contextmanager
def _remote(address: str, timeout: float, worker_wait: float) -> Iterator[Cluster]:
    from distributed import Client

    _probe(address, timeout)
    error = ""
    with _quiet_logs(), _quiet_unraisable():
        try:
            client = Client(address, timeout=f"{timeout}s", set_as_default=False)
        except (OSError, TimeoutError) as exc:
            error = f"no Dask scheduler answered at {address} within {timeout:g} s ({_reason(exc)})"
        except Exception as exc:  # something else is listening there
            error = f"{address} answered, but not as a Dask scheduler ({type(exc).__name__})"
        gc.collect()  # the half-made client closes here, its complaints silenced
    if error:
        raise ClusterError(error)
    try:
        try:
            client.wait_for_workers(1, timeout=worker_wait)
        except TimeoutError as exc:
            raise ClusterError(f"no worker joined the Dask scheduler at {address} within "
                               f"{worker_wait:g} s") from exc
        yield Cluster(client, len(client.scheduler_info(n_workers=-1)["workers"]), address)
    finally:
        client.close()


@contextlib.contextmanager
def _local(workers: int | None, threads: int, device: str, tasks: int | None) -> Iterator[Cluster]:
    from distributed import Client, LocalCluster

    if workers is not None and workers < 1:
        raise ClusterError(f"workers must be >= 1, got {workers}")
    if threads < 1:
        raise ClusterError(f"threads must be >= 1, got {threads}")
    if workers is not None:
        n = workers
    elif device.startswith("cuda"):
        n = 1 if ":" in device else max(1, gpu_count())
    else:
        n = max(1, usable_cores() // threads)
    n = max(1, min(n, tasks)) if tasks else n
    held = _SignalsHeld()
    # the fork server's start method stays set until the cluster is closed: a nanny restarts a
    # worker that died by the method set at that moment
    with contextlib.ExitStack() as forkserver:
        try:
            with warnings.catch_warnings():  # the scheduler's HTTP port taken: it picks another
                warnings.filterwarnings("ignore", message="Port .* is already in use")
                with held:
                    forkserver.enter_context(_workers_from_a_sigint_ignoring_forkserver())
                    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                           host="127.0.0.1", dashboard_address=None,
                                           silence_logs=_WORKER_LOG_LEVEL,
                                           env={"RAYSIM_THREADS": str(threads)})
        except (RuntimeError, OSError) as exc:
            held.deliver()
            raise ClusterError(f"could not start a local Dask cluster of {n} workers "
                               f"({_reason(exc)})") from exc
        try:
            held.deliver()  # a Ctrl-C or SIGTERM of the start acts now, with the cluster to close
            client = Client(cluster, set_as_default=False)
            try:
                yield Cluster(client, n, "local")
            finally:
                client.close()
                _stop_workers(cluster)
        finally:
            cluster.close()


@contextlib.contextmanager
def _workers_from_a_sigint_ignoring_forkserver() -> Iterator[None]:
    """Start local workers from a fork server that ignores SIGINT, so that they ignore it.

    Ctrl-C reaches the whole foreground process group: the client alone should stop, and it
    stops the workers quietly as it leaves; a worker that took the KeyboardInterrupt would
    print its own tracebacks. A fork server started with SIGINT ignored passes that on to every
    process it forks (Python keeps an inherited SIG_IGN). Ignoring SIGINT in this process only
    for the moment the server starts keeps Ctrl-C working here: ignoring it for the whole start
    of the cluster, as before, lost a Ctrl-C of that second, and the run went on to exit 0.
    The server is per process; one already running (started by something else) is used as it
    is. Only the main thread can change a handler: elsewhere, the server starts as it is.

    Hold this for as long as the cluster lives, not only while it starts: a nanny that restarts
    a worker which died (killed, out of memory) starts the new process by the method Dask's
    configuration names at that moment, and by Dask's default, spawn, the new worker takes
    Ctrl-C and prints its tracebacks.
    """
    import multiprocessing.forkserver

    import dask
    from distributed.utils import get_mp_context

    with dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"}):
        get_mp_context()  # the server's preloaded modules, set before it starts
        if threading.current_thread() is threading.main_thread():
            previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
            try:
                multiprocessing.forkserver.ensure_running()
            finally:
                signal.signal(signal.SIGINT, previous)
        yield


class _SignalsHeld:
    """Hold SIGINT and SIGTERM while a local cluster starts, and deliver them after.

    Raised in the middle of the start, they left a half-made cluster to Dask's exit hook (its
    traceback after the one line); delivered once the cluster exists, the usual clean-up
    closes it. Only the main thread can change a handler: elsewhere, nothing is held.
    """

    _SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self._previous: dict[int, Any] = {}
        self._arrived: list[int] = []

    def _record(self, signum: int, frame: object) -> None:
        self._arrived.append(signum)

    def __enter__(self) -> _SignalsHeld:
        if threading.current_thread() is threading.main_thread():
            for sig in self._SIGNALS:
                self._previous[sig] = signal.signal(sig, self._record)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()

    def deliver(self) -> None:
        """Raise the signals that arrived while held, once each, to this process's handlers."""
        for sig in dict.fromkeys(self._arrived):
            signal.raise_signal(sig)
        self._arrived.clear()


def _stop_workers(cluster: Any, timeout_s: float = 30.0) -> None:
    """Stop a local cluster's workers before its scheduler, and wait until it has seen them go.

    Closing the cluster at once stops the scheduler first; a worker whose heartbeat is in
    flight then logs a long "Failed to communicate with scheduler during heartbeat" traceback
    after a run that succeeded. Workers that have left send no heartbeat.
    """
    cluster.scale(0)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if not cluster.scheduler_info.get("workers") and not cluster.workers:
            return
        time.sleep(0.05)


def worker_device(device: str, name: Any) -> str:
    """The Warp device a worker named ``name`` uses for ``device`` (see the module docs)."""
    if device != "cuda":
        return device
    count = gpu_count()
    match = re.search(r"(\d+)$", str(name))
    index = int(match.group(1)) % count if match and count else 0
    return f"cuda:{index}"


def _probe(address: str, timeout: float) -> None:
    """Fail fast, in one line, unless a Dask scheduler answers at ``address`` within ``timeout``.

    A plain TCP connection first (a refused port or an unknown host fails at once: Dask's own
    connect retries those until its timeout), then one ``identity`` request, so that a server
    that accepts and never answers fails after ``timeout`` instead of hanging the client.
    """
    match = _ADDRESS.fullmatch(address)
    if match is None or match["scheme"] not in (None, "tcp", "tls", "ws", "wss"):
        return  # inproc, ucx: no plain TCP port to try
    host, port = match["host"].strip("[]"), int(match["port"])
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except ConnectionRefusedError as exc:
        raise ClusterError(f"cannot reach the Dask scheduler at {address}: connection refused "
                           "(is the scheduler running, on that port?)") from exc
    except TimeoutError as exc:
        raise ClusterError(f"cannot reach the Dask scheduler at {address} within {timeout:g} s "
                           "(no answer: host down or port filtered?)") from exc
    except OSError as exc:
        raise ClusterError(f"cannot reach the Dask scheduler at {address} "
                           f"({exc.strerror or _reason(exc)})") from exc
    _ask_identity(address, timeout)


def _ask_identity(address: str, timeout: float) -> None:
    """Send the scheduler one ``identity`` request and wait for its reply, within ``timeout``."""
    import asyncio

    from distributed.comm import connect as comm_connect

    async def ask() -> None:
        comm = await comm_connect(address, timeout=timeout)
        try:
            await comm.write({"op": "identity", "reply": True})
            await comm.read()
        finally:
            comm.abort()

    with _quiet_logs():
        try:
            asyncio.run(asyncio.wait_for(ask(), timeout))
        except TimeoutError:
            raise ClusterError(f"the Dask scheduler at {address} did not answer within "
                               f"{timeout:g} s (something else listening there?)") from None
        except (OSError, ValueError) as exc:
            raise ClusterError(f"cannot reach the Dask scheduler at {address} "
                               f"({_reason(exc)})") from None


@contextlib.contextmanager
def _quiet_unraisable() -> Iterator[None]:
    """Silence errors raised in finalisers (a client that never connected, closing)."""
    hook = sys.unraisablehook
    sys.unraisablehook = lambda unraisable: None
    try:
        yield
    finally:
        sys.unraisablehook = hook


@contextlib.contextmanager
def _quiet_logs() -> Iterator[None]:
    """Keep distributed's own connection-retry logging off the user's terminal."""
    logger = logging.getLogger("distributed")
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        logger.setLevel(level)


def _reason(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
