"""Blocks of sphere points as Dask tasks: the job on each worker, the task, the client's loop.

A *job* (:class:`Job`) is one field to compute: a small, picklable description (a scene's
text and options, or a forward model's surface) that builds the heavy context (reflectors,
quadratures, edges, elements: a :class:`raysim.simulate.BlockContext`) in the process that
needs it. The client registers the job on the cluster as a worker plugin (:class:`JobPlugin`):
every worker, and every worker that joins later (a nanny's restart included), receives the
description once; nothing heavy is pickled, and no task carries more than its job's key and
its block's bounds. Each worker process builds the context on its first block and keeps it
(at most :data:`CONTEXTS_KEPT` jobs per process).

A task (:func:`run_block`) evaluates the points lo..hi-1 and, with a partial store the worker
can reach, writes them there itself and returns only figures; otherwise it returns the arrays
and the client keeps or writes them. A block already marked done in the store is skipped.

Threads: a worker runs its tasks on its Dask threads; each Warp launch uses
``RAYSIM_THREADS`` CPU threads (the job's ``threads``). Devices: each worker picks its own GPU
for ``cuda`` (:func:`raysim.distributed.cluster.worker_device`).
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
import uuid
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from distributed.diagnostics.plugin import WorkerPlugin

from raysim.distributed.cluster import ClusterError, worker_device
from raysim.distributed.partial import PartialStore
from raysim.distributed.process import load_kernels, tune_malloc
from raysim.optics.sources import BLOCK_ALIGN
from raysim.simulate import BlockContext

CONTEXTS_KEPT = 2


class Job(Protocol):
    """One field computed in blocks (see the module docs). Picklable, small."""

    key: str  # the job's fingerprint: one context per process per key
    n_points: int
    device: str  # cpu, cuda (each worker takes its own GPU) or cuda:N
    threads: int  # CPU threads of each Warp launch in a worker

    def parts(self) -> dict[str, tuple[int, ...]]:
        """The arrays a block gives: name -> tail shape (float64, one row per point)."""
        ...

    def build(self, device: str, keep: bool) -> BlockContext:
        """The job's context on ``device`` (``keep``: several blocks will use it)."""
        ...


DEFAULT_BLOCK = {"cpu": 1024, "cuda": 32768}  # points per block (a GPU wants many threads)


def block_bounds(n_points: int, block_size: int) -> list[tuple[int, int]]:
    """(lo, hi) of each block of ``block_size`` points (the last one shorter)."""
    return [(lo, min(lo + block_size, n_points)) for lo in range(0, n_points, block_size)]


def block_size_for(n_points: int, device: str, requested: int | None = None) -> int:
    """Points per block: ``requested`` (checked), else :data:`DEFAULT_BLOCK` for the device,
    at most the grid rounded up; always a multiple of :data:`~raysim.optics.sources.BLOCK_ALIGN`."""
    if requested is not None:
        if requested < BLOCK_ALIGN or requested % BLOCK_ALIGN:
            raise ClusterError(f"block size must be a positive multiple of {BLOCK_ALIGN} points, "
                               f"got {requested}")
        return int(requested)
    size = DEFAULT_BLOCK["cpu" if device == "cpu" else "cuda"]
    return min(size, max(BLOCK_ALIGN, -(-n_points // BLOCK_ALIGN) * BLOCK_ALIGN))


# --- the worker side ---------------------------------------------------------------------
_lock = threading.Lock()
_jobs: dict[str, Job] = {}
_contexts: OrderedDict[str, Built] = OrderedDict()
_loaded: set[str] = set()


@dataclass(frozen=True)
class Built:
    """A job's context in this process, with its digest, device and build time (s)."""

    context: BlockContext
    digest: str
    device: str
    seconds: float


def plugin_name(key: str) -> str:
    return f"raysim-job-{key[:16]}"


class JobPlugin(WorkerPlugin):
    """Hands a job to every worker (and to any that joins later)."""

    def __init__(self, job: Job) -> None:
        self.job = job
        self.name = plugin_name(job.key)

    def setup(self, worker: Any = None) -> None:
        # light work only: this runs on the worker's event loop; the context is built in a task
        os.environ["RAYSIM_THREADS"] = str(int(self.job.threads))
        tune_malloc()
        with _lock:
            _jobs[self.job.key] = self.job

    def teardown(self, worker: Any = None) -> None:
        with _lock:
            _jobs.pop(self.job.key, None)
            _contexts.pop(self.job.key, None)


def built(key: str, name: Any = None) -> tuple[Built, bool]:
    """The context of job ``key`` in this process, built on first use (``name``: the worker's),
    and whether this call built it."""
    with _lock:
        if key in _contexts:
            _contexts.move_to_end(key)
            return _contexts[key], False
        job = _jobs.get(key)
        if job is None:
            raise ClusterError(f"job {key[:12]} is not registered on this worker")
        device = worker_device(job.device, name)
        start = time.perf_counter()
        if device not in _loaded:
            load_kernels(device)  # under the kernel cache's lock: one process compiles
            _loaded.add(device)
        context = job.build(device, True)
        context.attrs()  # the elements made once: counts and digest known
        made = Built(context, context.digest(), device, time.perf_counter() - start)
        _contexts[key] = made
        while len(_contexts) > CONTEXTS_KEPT:
            _contexts.popitem(last=False)
        return made, True


def _worker_name() -> Any:
    try:
        from distributed import get_worker

        return get_worker().name
    except ValueError:  # not in a worker: a test calling the task directly
        return None


def run_block(key: str, index: int, lo: int, hi: int, store: str | None = None) -> dict[str, Any]:
    """Task: block ``index`` (points lo..hi-1) of job ``key``; see the module docs."""
    start, cpu = time.perf_counter(), time.process_time()
    partial = _reachable(store, key)
    if partial is not None and partial.marker(index) is not None:
        return {"index": index, "skipped": True}
    name = _worker_name()
    made, fresh = built(key, name)
    arrays, figures = made.context.evaluate(lo, hi)
    record = {"figures": {k: float(v) for k, v in figures.items()}, "digest": made.digest,
              "device": made.device, "worker": str(name), "build_seconds": made.seconds if fresh else 0.0,
              "wall": time.perf_counter() - start, "cpu": time.process_time() - cpu}
    meta: dict[str, Any] = {"index": index, "skipped": False, "attrs": made.context.attrs(), **record}
    if partial is not None and partial.exists():
        partial.set_context(meta["attrs"])
        meta["count"] = partial.write(index, arrays, record)
    else:
        meta["arrays"] = arrays
    return meta


def _reachable(store: str | None, key: str) -> PartialStore | None:
    """The partial store at ``store`` when this process sees it (made for job ``key``)."""
    if store is None or not os.path.isfile(os.path.join(store, "zarr.json")):
        return None
    partial = PartialStore.open(store)
    if partial.fingerprint != key:
        raise ClusterError(f"{store}: this worker sees a partial store of another run")
    return partial


# --- the client side ---------------------------------------------------------------------
def run_blocks(client: Any, job: Job, blocks: Iterable[int], bounds: list[tuple[int, int]],
               store: PartialStore | None = None,
               on_block: Callable[[dict[str, Any]], None] | None = None) -> None:
    """Compute ``blocks`` (indices into ``bounds``) of ``job`` on ``client``'s cluster.

    Each finished block's record goes to ``on_block`` as it arrives; when the worker could not
    write it into ``store`` the record carries its ``arrays``, which are written here (with a
    store) or left to ``on_block``. A block that fails, or kills its worker every time Dask
    retries it, stops the run with a ClusterError naming the block.
    """
    from distributed import KilledWorker, as_completed

    indices = list(blocks)
    if not indices:
        return
    name = plugin_name(job.key)
    try:
        client.register_plugin(JobPlugin(job), name=name)
    except Exception as exc:
        raise ClusterError(f"the Dask workers could not take the job ({_reason(exc)})") from exc
    token = uuid.uuid4().hex[:8]
    path = str(store.path) if store is not None else None
    futures = {client.submit(run_block, job.key, i, *bounds[i], path, pure=False,
                             key=f"raysim-block-{job.key[:10]}-{token}-{i}"): i for i in indices}
    try:
        for future in as_completed(list(futures), loop=client.loop):
            index = futures[future]
            try:
                meta = future.result()
            except KilledWorker as exc:
                raise ClusterError(f"block {index}: its worker died each time it ran it "
                                   "(out of memory? see the workers' logs)") from exc
            except Exception as exc:
                raise ClusterError(f"block {index} failed on a worker ({_reason(exc)})") from exc
            future.release()
            if store is not None and "arrays" in meta:
                store.set_context(meta["attrs"])
                meta["count"] = store.write(index, meta.pop("arrays"),
                                            {k: meta[k] for k in RECORD_KEYS})
            if on_block is not None:
                on_block(meta)
    finally:
        client.cancel([f for f in futures if not f.done()])
        with contextlib.suppress(Exception):
            client.unregister_worker_plugin(name)


RECORD_KEYS = ("figures", "digest", "device", "worker", "build_seconds", "wall", "cpu")


def assemble(parts: dict[str, tuple[int, ...]], n_points: int,
             blocks: dict[tuple[int, int], dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """The whole grid's arrays from blocks ((lo, hi) -> arrays), copied into place."""
    out = {name: np.full((n_points, *tail), np.nan) for name, tail in parts.items()}
    for (lo, hi), arrays in blocks.items():
        for name in parts:
            out[name][lo:hi] = arrays[name]
    return out


def _reason(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


class BlockRunner:
    """Evaluates jobs in blocks on a Dask cluster, assembled in the client's memory.

    The cluster (:func:`raysim.distributed.cluster.connect` with ``connect_args``) is opened on
    the first :meth:`evaluate` and kept until :meth:`close`: a run that never needs it starts
    none. ``evaluate(job, progress)`` returns the whole grid's arrays (no partial store: a
    forward model's field is short-lived); ``threads`` sets the job's CPU threads per launch.
    """

    def __init__(self, connect_args: dict[str, Any], threads: int = 1,
                 block_size: int | None = None) -> None:
        self.connect_args, self.threads, self.block_size = connect_args, int(threads), block_size
        self._stack = contextlib.ExitStack()
        self._cluster: Any = None
        self.blocks = 0
        self.seconds = 0.0

    @property
    def cluster(self) -> Any:
        if self._cluster is None:
            from raysim.distributed.cluster import connect

            self._cluster = self._stack.enter_context(connect(**self.connect_args))
        return self._cluster

    def close(self) -> None:
        self._stack.close()
        self._cluster = None

    def evaluate(self, job: Job, progress: Callable[[str, float], None] | None = None
                 ) -> dict[str, np.ndarray]:
        from dataclasses import replace

        start = time.perf_counter()
        job = replace(job, threads=self.threads)  # type: ignore[type-var]
        bounds = block_bounds(job.n_points, block_size_for(job.n_points, job.device, self.block_size))
        parts: dict[tuple[int, int], dict[str, np.ndarray]] = {}
        report = progress or (lambda stage, fraction: None)

        def keep(meta: dict[str, Any]) -> None:
            parts[bounds[meta["index"]]] = meta["arrays"]
            report(f"blocks {len(parts)}/{len(bounds)}", len(parts) / len(bounds))

        report(f"blocks 0/{len(bounds)}", 0.0)
        run_blocks(self.cluster.client, job, range(len(bounds)), bounds, None, keep)
        self.blocks += len(bounds)
        self.seconds += time.perf_counter() - start
        return assemble(job.parts(), job.n_points, parts)


@contextlib.contextmanager
def block_runner(scheduler: str | None = None, *, workers: int | None = None, threads: int = 1,
                 device: str = "cpu", block_size: int | None = None) -> Iterator[BlockRunner]:
    """A :class:`BlockRunner` on ``scheduler`` or on a local cluster of ``workers`` (opened when
    first needed), closed on exit. Bad addresses and devices are refused here, at once."""
    from raysim.distributed.cluster import scheduler_address

    address = scheduler_address(scheduler) if scheduler else None
    if address is None and device != "cpu":
        from raysim.optics import runtime

        runtime.resolve_device(device)
    if block_size is not None:
        block_size_for(block_size, device, block_size)
    runner = BlockRunner({"scheduler": address, "workers": workers, "threads": threads,
                          "device": device}, threads, block_size)
    try:
        yield runner
    finally:
        runner.close()
