"""Warp set-up shared by every kernel module: kernel cache, device choice, threaded launches.

Warp runs one CPU launch on one thread, so :func:`launch` splits a 1-D launch into slices
that run in parallel Python threads (Warp releases the GIL inside a launch). Every kernel
launched this way takes ``offset: int`` as its last input and indexes ``wp.tid() + offset``.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextvars import ContextVar
from pathlib import Path
from typing import Any

import numpy as np

from raysim.errors import DeviceError

_lock = threading.Lock()
_ready = False


def _repo_cache() -> Path | None:
    """The ignored ``.cache/warp`` folder of a source checkout, if raysim runs from one."""
    root = Path(__file__).resolve().parent.parent
    if (root / "pyproject.toml").is_file() and os.access(root, os.W_OK):
        return root / ".cache" / "warp"
    return None


def init() -> Any:
    """Import and initialise Warp once (quietly), with the kernel cache set; return ``warp``."""
    global _ready
    import warp as wp

    with _lock:
        if not _ready:
            wp.config.log_level = 30  # warnings and errors only: no banner, no load timings
            cache = os.environ.get("WARP_CACHE_PATH") or _repo_cache()
            if cache is not None:
                wp.config.kernel_cache_dir = str(cache)
            with _quiet_stderr():
                # Warp's native layer prints a warning when no CUDA driver exists; a
                # CPU-only user needs no such line, and a CUDA request fails clearly anyway
                wp.init()
            _ready = True
    return wp


@contextlib.contextmanager
def _quiet_stderr():
    """Silence file descriptor 2 (native prints included) for the duration."""
    try:
        saved = os.dup(2)
    except OSError:  # pragma: no cover - no stderr to silence
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        sys.stderr.flush()
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


def resolve_device(device: str | None) -> str:
    """Map ``cpu`` / ``cuda`` / ``cuda:N`` / None to a Warp device name, or raise DeviceError."""
    wp = init()
    name = device or "cpu"
    if name == "cpu":
        return "cpu"
    if name.startswith("cuda"):
        if not wp.is_cuda_available():
            raise DeviceError(f"device {name!r} requested but no CUDA GPU is available here")
        return name if ":" in name else "cuda:0"
    raise DeviceError(f"unknown device {name!r}: use cpu or cuda")


def cpu_threads() -> int:
    """Threads for CPU launches: RAYSIM_THREADS, else the cores this process may use."""
    env = os.environ.get("RAYSIM_THREADS")
    if env:
        return max(1, int(env))
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - non-Linux
        return max(1, os.cpu_count() or 1)


#: slices of a CPU launch that accumulates (``private``), whatever the threads: the order of
#: its float sums must not depend on the machine
ACCUMULATING_SLICES = 8


class Cancelled(Exception):
    """Raised by :func:`launch` in work run by :func:`cancellable` once its event is set: the
    caller that set it is already unwinding with its own exception."""


#: the event of the :func:`cancellable` work running in this context (None: not cancellable)
_CANCEL: ContextVar[threading.Event | None] = ContextVar("raysim_cancel", default=None)


def cancellable(event: threading.Event, work: Callable[[], Any]) -> Any:
    """``work()``, whose kernel launches raise :class:`Cancelled` once ``event`` is set: work
    handed to another thread (one reflector's sum while the other's elements are made) stops
    within one launch of its caller's error or Ctrl-C, instead of running to its end while the
    caller waits for its thread."""
    token = _CANCEL.set(event)
    try:
        return work()
    finally:
        _CANCEL.reset(token)


def launch(kernel: Any, dim: int, inputs: Sequence[Any], device: str, min_chunk: int = 4096,
           private: Sequence[int] = ()) -> None:
    """Launch a 1-D ``kernel`` over ``dim`` items; on the CPU, in slices across threads.

    ``inputs`` excludes the trailing ``offset`` argument, which this function appends.
    ``private`` lists the positions in ``inputs`` of arrays the kernel accumulates into with
    ``wp.atomic_add``: Warp's CPU atomics are plain adds, so each slice gets its own zeroed
    copy and the copies are summed into the original afterwards, in slice order. Such a launch
    is cut into :data:`ACCUMULATING_SLICES` slices whatever the number of threads, so its sums
    are the same to the last bit on any machine (a dataset resumed with other ``--threads``
    stays bit-identical).
    """
    wp = init()
    event = _CANCEL.get()
    if event is not None and event.is_set():
        raise Cancelled("the work was cancelled by its caller")
    if dim <= 0:
        return
    threads = cpu_threads() if device == "cpu" else 1
    slices = ACCUMULATING_SLICES if private and device == "cpu" else threads
    n = max(1, min(slices, dim // min_chunk))
    if n == 1:
        wp.launch(kernel, dim=dim, inputs=[*inputs, 0], device=device)
        wp.synchronize_device(device)
        return
    # the first launch compiles or loads the module; do it once before the threads race
    wp.load_module(kernel.module, device=device)
    bounds = [dim * k // n for k in range(n + 1)]
    copies = [
        {i: wp.zeros_like(inputs[i]) for i in private} if k > 0 else {} for k in range(n)
    ]

    def run(k: int) -> None:
        lo, hi = bounds[k], bounds[k + 1]
        args = [copies[k].get(i, a) for i, a in enumerate(inputs)]
        if hi > lo:
            wp.launch(kernel, dim=hi - lo, inputs=[*args, lo], device=device)

    with ThreadPoolExecutor(max_workers=max(1, min(n, threads))) as pool:
        list(pool.map(run, range(n)))
    for i in private:
        total = inputs[i].numpy()  # a view of the CPU array's memory
        for k in range(1, n):
            total += copies[k][i].numpy()


def warp_mesh(vertices, faces, device) -> tuple[Any, Any]:
    """A Warp BVH mesh of triangles (``vertices`` (n, 3) m, ``faces`` (m, 3)) on ``device``,
    and its float32 points array (kept alive beside the mesh; the BVH finds faces only, the
    geometry is recomputed in float64 by the callers)."""
    wp = init()
    points = wp.array(np.asarray(vertices).astype(np.float32), dtype=wp.vec3, device=device)
    indices = wp.array(np.asarray(faces).astype(np.int32).ravel(), dtype=wp.int32, device=device)
    return wp.Mesh(points=points, indices=indices), points
