"""What runs in a Dask worker: the set-up plugin, the per-process context, the two tasks.

A task gets only the store path, the spec's fingerprint and an index; it reads the spec from
the store (once per process), draws the sample, simulates it and writes its region of the
store itself, returning a few numbers. Any exception inside a sample is caught and the sample
is recorded as failed with its reason, so the worker goes on with the next one.

The plugin runs once per worker process: :func:`raysim.distributed.process.prepare_process`
fixes the CPU threads of each Warp launch, tunes malloc (Dask's setting doubled the CPU time of
a paper-grid sample) and loads every Warp kernel under a file lock in the kernel cache.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin

from raysim.dataset.engine import ideal_intensity, simulate_sample
from raysim.dataset.integrity import spec_data_names
from raysim.dataset.sampling import draw_sample
from raysim.dataset.spec import DatasetError, DatasetSpec, parse_spec
from raysim.dataset.store import Writer, open_readonly, refuse_other_versions
from raysim.distributed.process import prepare_process, tune_malloc  # noqa: F401  (re-exported)

_lock = threading.Lock()


class DatasetWorkerPlugin(WorkerPlugin):
    """Prepare a worker process for dataset samples (threads per launch, Warp kernels)."""

    name = "raysim-dataset"

    def __init__(self, threads: int = 1, device: str = "cpu") -> None:
        self.threads = int(threads)
        self.device = device

    def setup(self, worker: Any = None) -> None:
        prepare_process(self.threads, self.device)


@dataclass(frozen=True)
class Context:
    """One process's view of a store: the spec it was made from and a writer."""

    spec: DatasetSpec
    writer: Writer


@lru_cache(maxsize=4)
def context(store: str, fingerprint: str) -> Context:
    """The spec (from the store's attributes) and an open writer, once per process."""
    group = open_readonly(store)
    attrs = group.attrs
    spec = parse_spec(str(attrs["spec"]), source=str(attrs["spec_source"]),
                      base=Path(str(attrs["spec_base"])))
    if spec.fingerprint != fingerprint:
        raise DatasetError(f"{store}: the store's spec changed under a running dataset")
    refuse_other_versions(store, attrs)  # a worker on another machine, with other packages
    import zarr

    return Context(spec, Writer(zarr.open_group(store, mode="r+"), spec_data_names(spec), spec.seed))


def run_ideal(store: str, fingerprint: str, f_index: int, device: str = "cpu") -> dict[str, Any]:
    """Task: the ideal intensity of frequency ``f_index``, written into the store."""
    ctx = context(store, fingerprint)
    start = time.perf_counter()
    try:
        ctx.writer.ideal(f_index, ideal_intensity(ctx.spec, f_index, device))
        return {"frequency": f_index, "ok": True, "error": "", "seconds": time.perf_counter() - start}
    except Exception as exc:  # recorded, never raised: the samples still go on
        reason = _reason(exc)
        ctx.writer.ideal(f_index, None, reason)
        return {"frequency": f_index, "ok": False, "error": reason, "seconds": time.perf_counter() - start}


def run_sample(store: str, fingerprint: str, index: int, device: str = "cpu") -> dict[str, Any]:
    """Task: draw, simulate and write sample ``index``; a failure is recorded, not raised."""
    ctx = context(store, fingerprint)
    spec, writer = ctx.spec, ctx.writer
    start = time.perf_counter()
    cpu_start = time.process_time()
    try:
        draw = draw_sample(spec, index)
        writer.params(index, draw.params, spec.frequencies[draw.frequency_index],
                      spec.grid.evaluate(draw.deformation))
        values = simulate_sample(spec, draw.deformation, draw.frequency_index, device)
        measured = None if draw.effects is None else \
            draw.measured(values, ideal_intensity(spec, draw.frequency_index, device), spec)
        seconds = time.perf_counter() - start
        writer.done(index, values, seconds, time.process_time() - cpu_start, measured)
        return {"index": index, "ok": True, "error": "", "seconds": seconds}
    except Exception as exc:
        reason = _reason(exc)
        seconds = time.perf_counter() - start
        writer.failed(index, reason, seconds)
        return {"index": index, "ok": False, "error": reason, "seconds": seconds}


def _reason(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
