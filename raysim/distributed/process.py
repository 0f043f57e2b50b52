"""Setting up a worker process for Warp work: threads per launch, malloc, kernels loaded once.

Shared by every Dask worker raysim uses (dataset samples, blocks of sphere points):

- ``RAYSIM_THREADS`` fixes the CPU threads of each Warp launch (:func:`raysim.optics.runtime.cpu_threads`);
- :func:`tune_malloc` lets glibc keep freed memory for reuse: Dask starts workers with
  ``MALLOC_TRIM_THRESHOLD_`` set, which makes every array over 128 KiB a fresh ``mmap`` and
  doubled the CPU time of a paper-grid GO sample (page faults on the many large temporaries);
- :func:`load_kernels` compiles or loads every kernel of :mod:`raysim.optics.kernels` on the
  device under a file lock in the kernel cache, so one process compiles and the others load.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import fcntl
import importlib
import os
import pkgutil
from collections.abc import Iterator
from pathlib import Path

from raysim.optics import runtime as warp_runtime

M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters
MMAP_THRESHOLD = 32 << 20  # bytes: glibc's largest; smaller arrays come from the heap
TRIM_THRESHOLD = 256 << 20  # bytes of free heap kept before returning memory to the OS


def prepare_process(threads: int, device: str = "cpu") -> None:
    """Set ``RAYSIM_THREADS``, tune malloc, and compile or load every Warp kernel once."""
    os.environ["RAYSIM_THREADS"] = str(int(threads))
    tune_malloc()
    load_kernels(device)


def load_kernels(device: str = "cpu") -> None:
    """Compile or load every kernel module of :mod:`raysim.optics.kernels` on ``device``
    (including the per-kernel modules of the radiation kernels) under the cache's file lock."""
    wp = warp_runtime.init()
    dev = warp_runtime.resolve_device(device)
    import raysim.optics.kernels as kernels

    cache = Path(str(wp.config.kernel_cache_dir))
    cache.mkdir(parents=True, exist_ok=True)
    with file_lock(cache / ".raysim-compile.lock"):
        for info in pkgutil.iter_modules(kernels.__path__, prefix="raysim.optics.kernels."):
            module = importlib.import_module(info.name)
            with contextlib.suppress(RuntimeError):  # a module without Warp code
                wp.load_module(module, device=dev)
            for value in vars(module).values():  # kernels made with module="unique"
                if isinstance(value, wp.Kernel) and value.module.name != module.__name__:
                    wp.load_module(value.module, device=dev)


def tune_malloc() -> bool:
    """Serve arrays below 32 MiB from glibc's heap and keep up to 256 MiB of it when freed.

    Returns False (and changes nothing) where the C library has no ``mallopt``.
    """
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # pragma: no cover - not glibc
        return False
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD))


@contextlib.contextmanager
def file_lock(path: Path) -> Iterator[None]:
    """An exclusive advisory lock on ``path`` (created if missing) for the duration."""
    with open(path, "a+") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
