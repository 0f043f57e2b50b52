"""Warp set-up shared by every kernel module: kernel cache, device choice, threaded launches.

Warp runs one CPU launch on one thread, so :func:`launch` splits a 1-D launch into slices
that run in parallel Python threads (Warp releases the GIL inside a launch). Every kernel
launched this way takes ``offset: int`` as its last input and indexes ``wp.tid() + offset``.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

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
            wp.config.quiet = True
            cache = os.environ.get("WARP_CACHE_PATH") or _repo_cache()
            if cache is not None:
                wp.config.kernel_cache_dir = str(cache)
            wp.init()
            _ready = True
    return wp


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


def launch(kernel: Any, dim: int, inputs: Sequence[Any], device: str, min_chunk: int = 4096) -> None:
    """Launch a 1-D ``kernel`` over ``dim`` items; on the CPU, in slices across threads.

    ``inputs`` excludes the trailing ``offset`` argument, which this function appends.
    """
    wp = init()
    if dim <= 0:
        return
    threads = cpu_threads() if device == "cpu" else 1
    n = max(1, min(threads, dim // min_chunk))
    if n == 1:
        wp.launch(kernel, dim=dim, inputs=[*inputs, 0], device=device)
        wp.synchronize_device(device)
        return
    # the first launch compiles or loads the module; do it once before the threads race
    wp.load_module(kernel.module, device=device)
    bounds = [dim * k // n for k in range(n + 1)]

    def run(k: int) -> None:
        lo, hi = bounds[k], bounds[k + 1]
        if hi > lo:
            wp.launch(kernel, dim=hi - lo, inputs=[*inputs, lo], device=device)

    with ThreadPoolExecutor(max_workers=n) as pool:
        list(pool.map(run, range(n)))
