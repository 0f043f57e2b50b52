"""The client side of a dataset run: store set-up, the Dask cluster, tasks and progress.

The client creates (or checks) the store, finds what is missing (samples whose completion
marker is not set, the ideal intensity of each frequency), submits one task per missing item
and counts the outcomes as they arrive; the workers write the data. The client itself writes
only the store's skeleton and, when a task killed its worker every time Dask retried it, the
failure record of that sample.

The cluster is a local one by default (worker processes with one thread each, bound to
127.0.0.1, no dashboard), or any running scheduler (``scheduler="tcp://host:port"``) whose
workers can import raysim and reach the store's path.
"""

from __future__ import annotations

import errno
import shutil
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from raysim.dataset import integrity
from raysim.dataset import store as zstore
from raysim.dataset.spec import DatasetError, DatasetSpec, load_spec
from raysim.dataset.store_layout import store_bytes
from raysim.dataset.worker import DatasetWorkerPlugin, run_ideal, run_sample
from raysim.distributed.cluster import connect, scheduler_address
from raysim.progress import Progress


@dataclass(frozen=True)
class RunReport:
    """Outcome of :func:`generate`. Counts are samples; ``seconds`` wall-clock time."""

    store: str
    samples: int
    done: int  # complete in the store after this run
    failed: int  # recorded as failed in the store after this run
    computed: int  # finished (done or failed) by this run
    skipped: int  # already complete before this run
    workers: int
    seconds: float
    failures: tuple[tuple[int, str], ...]  # (sample, reason) of this run's failures, first 20
    ideal_failures: tuple[tuple[int, str], ...]  # (frequency index, reason)
    repaired: int = 0  # done samples (and ideal intensities) that failed verification: recomputed
    rewritten: tuple[str, ...] = ()  # creation-time arrays and attributes rewritten from the spec
    cleared: tuple[tuple[str, int], ...] = ()  # (array, chunks): unreadable records of done items, reset
    nothing_to_resume: bool = False  # asked to resume, and no store was there: a new one made

    @property
    def samples_per_second(self) -> float:
        return self.computed / self.seconds if self.seconds > 0 else float("nan")

    def summary(self) -> str:
        """One line for the user."""
        if not self.computed:  # an ideal intensity may still have been recomputed (repaired)
            line = (f"{self.store}: {self.done}/{self.samples} samples done, "
                    + ("no sample left to compute" if self.repaired or self.ideal_failures
                       else "nothing left to compute"))
        else:
            line = (f"{self.store}: {self.done}/{self.samples} samples done ({self.skipped} already "
                    f"there, {self.computed} computed on {self.workers} "
                    f"worker{'s' if self.workers != 1 else ''} in {self.seconds:.1f} s, "
                    f"{self.samples_per_second:.3g} samples/s)")
        if self.failed:
            index, reason = self.failures[0] if self.failures else (-1, "see the store's 'error'")
            line += f"; {self.failed} failed (sample {index}: {reason})"
        if self.ideal_failures:
            line += f"; the ideal intensity failed ({self.ideal_failures[0][1]})"
        if self.repaired:
            one = self.repaired == 1
            line += (f"; {self.repaired} done item{'' if one else 's'} failed verification and "
                     f"{'was' if one else 'were'} recomputed")
        if self.cleared:
            line += ("; unreadable, rewritten as unknown (NaN, or no error text): "
                     + ", ".join(f"{name} of {n} sample{'' if n == 1 else 's'}"
                                 if not name.startswith("ideal_") else f"{name} of {n} frequenc"
                                 f"{'y' if n == 1 else 'ies'}" for name, n in self.cleared))
        if self.nothing_to_resume:  # a mistyped store path would start a store elsewhere
            line += f"; --resume: no store was at {self.store} to complete, so a new one was made"
        return line + self._rewritten_note()

    def _rewritten_note(self) -> str:
        if not self.rewritten:
            return ""
        return f"; no longer matching the spec, rewritten from it: {', '.join(self.rewritten)}"


def generate(spec: DatasetSpec | str | Path, store: str | Path, *, workers: int | None = None,
             scheduler: str | None = None, resume: bool = False, device: str = "cpu",
             threads: int = 1, progress: Progress | None = None) -> RunReport:
    """Simulate every sample of ``spec`` into the Zarr store ``store`` on Dask.

    Parameters
    ----------
    spec : a :class:`DatasetSpec` or the path of a spec TOML file.
    store : the store's path (a folder ``*.zarr``; every worker must reach it).
    workers : local worker processes (default: the usable cores divided by ``threads``).
    scheduler : address of a running Dask scheduler (``tcp://host:port``) instead of a
        local cluster; ``workers`` is then ignored.
    resume : complete an existing store made by the same spec (done samples are kept once
        they match their checksums, pending, failed and unverified ones are computed; see
        :func:`raysim.dataset.store.verify`); without it an existing path is refused.
    device : Warp device of the traces (``cpu``; ``cuda`` on workers with a GPU).
    threads : CPU threads of each Warp launch in every worker (``RAYSIM_THREADS``). The
        result of a trace depends on it at round-off level, not on anything else, so a
        store is bit-identical for one value whatever the number of workers.
    progress : optional ``progress(stage, fraction)`` (:mod:`raysim.progress`): the stage
        reads ``N of M samples`` (and ``, K failed`` once some failed this run), the
        fraction is the share of samples done or failed.
    """
    start = time.perf_counter()
    spec = spec if isinstance(spec, DatasetSpec) else load_spec(spec)
    check_run_options(spec, store, workers=workers, scheduler=scheduler, device=device,
                      threads=threads, resume=resume)
    path = _store_path(store)
    zstore.remove_leftovers(path)
    group, created = _existing_store(path, spec, resume), False
    repaired, rewritten, cleared = 0, (), ()
    if group is not None:  # resume: check, then repair what the spec gives and recompute the rest
        repaired, rewritten, cleared = _check_and_repair(group, path, spec)
    if group is None:  # a new store: every sample and every frequency's ideal is pending
        pending, ideal_pending = np.arange(spec.samples), np.arange(len(spec.frequencies))
    else:
        pending = np.flatnonzero(zstore.status(group) != zstore.DONE)
        ideal_pending = np.flatnonzero(zstore.ideal_status(group) != zstore.DONE)
    skipped = spec.samples - len(pending)
    report = _sample_progress(progress)
    failures: list[tuple[int, str]] = []
    ideal_failures: list[tuple[int, str]] = []
    n_workers = 0
    if len(pending) or len(ideal_pending):
        # the cluster first: a scheduler that cannot be reached leaves no store behind
        with connect(scheduler, workers=workers, threads=threads,
                     tasks=len(pending) + len(ideal_pending)) as cluster:
            if group is None:
                group, created = zstore.create(path, spec), True
            report(skipped, 0, spec.samples)
            n_workers = cluster.workers
            try:
                _prepare_workers(cluster.client, threads, device)
                _run(cluster.client, path, spec, device, pending, ideal_pending,
                     zstore.Writer(group), report, skipped, failures, ideal_failures)
            except BaseException as exc:
                # a store this run created and that holds no finished sample is no store to
                # resume: remove it, so that the same command can simply be run again
                removed = created and np.all(zstore.status(group) == zstore.PENDING)
                if removed:
                    shutil.rmtree(path, ignore_errors=True)
                if isinstance(exc, OSError) and exc.errno in FULL_DISK:
                    raise DatasetError(_full_disk_line(path, removed)) from exc
                raise
    else:
        report(skipped, 0, spec.samples)
    final = zstore.status(group)
    return RunReport(
        store=path, samples=spec.samples, done=int(np.sum(final == zstore.DONE)),
        failed=int(np.sum(final == zstore.FAILED)), computed=len(pending), skipped=skipped,
        workers=n_workers, seconds=time.perf_counter() - start, failures=tuple(failures[:20]),
        ideal_failures=tuple(ideal_failures), repaired=repaired, rewritten=rewritten, cleared=cleared,
        nothing_to_resume=resume and created)


def _check_and_repair(group, path: str, spec: DatasetSpec) \
        -> tuple[int, tuple[str, ...], tuple[tuple[str, int], ...]]:
    """A resumed store checked before anything is written: every array of the spec's layout
    of the layout's shape, chunks and type (else refused, DatasetError). Then the metadata of
    the arrays whose ``zarr.json`` is missing or unreadable is rewritten from the layout (their
    chunks kept), every done sample and ideal intensity is checked against its checksum, the
    creation-time arrays and attributes that no longer match the spec are rewritten from it,
    the samples that failed (or lost their marker) are made pending, and the records of done
    items that no longer decode (times, error texts) are rewritten as unknown. Returns (samples
    and ideals made pending, what was rewritten, (record array, chunks rewritten))."""
    static = integrity.static_arrays(spec)
    repairs = integrity.check_store(group, path, spec, static)
    # a format-2 store has every array of its layout (check_format): one whose metadata was lost
    # is the layout's, so it is restored and its chunks verified, never taken for an older store
    integrity.restore_metadata(group, spec, repairs.metadata)
    names = integrity.spec_data_names(spec)
    # the spec's seeds, not the store's: a damaged seed array must not fail every sample
    bad, ideal_bad = zstore.verify(group, path, names, static["seed"])
    integrity.repair(group, repairs, spec)
    zstore.reset(group, bad, ideal_bad, names)
    cleared = zstore.clear_unreadable_records(group)
    return len(bad) + len(ideal_bad), repairs.names, tuple(cleared.items())


SampleReport = Callable[[int, int, int], None]  # (done in the store, failed this run, total)


def _sample_progress(progress: Progress | None) -> SampleReport:
    """(samples done in the store, failed this run, total) -> ``progress(stage, fraction)``."""
    def report(done: int, failed: int, total: int) -> None:
        if progress is not None:
            note = f", {failed} failed" if failed else ""
            progress(f"{done} of {total} samples{note}", (done + failed) / total if total else 1.0)

    return report


MAX_WORKERS = 1024
MAX_THREADS = 256


def check_run_options(spec: DatasetSpec, store: str | Path, *, workers: int | None = None,
                      scheduler: str | None = None, device: str = "cpu", threads: int = 1,
                      resume: bool = False) -> None:
    """Refuse options :func:`generate` cannot honour, before any work (DatasetError): worker
    and thread counts, the scheduler's address, the device, and a store path that is a file
    or the spec itself. Creates the store's parent folder."""
    from raysim.files import check_output, probe_writable

    for name, value, hi in (("--threads", threads, MAX_THREADS), ("--workers", workers, MAX_WORKERS)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)
                                  or not 1 <= value <= hi):
            raise DatasetError(f"{name} must be an integer in 1..{hi}, got {value!r}")
    if scheduler is not None:
        scheduler_address(scheduler)  # ClusterError, one line
    elif device != "cpu":  # local workers see this machine's devices
        from raysim.optics import runtime as warp_runtime

        warp_runtime.resolve_device(device)
    text = str(store)
    if "://" in text:
        return
    path = Path(text).expanduser()
    check_output(path, [("dataset spec", spec.source if Path(spec.source).is_file() else None)],
                 DatasetError)
    if path.exists() and not path.is_dir():
        raise DatasetError(f"{path}: exists and is not a Zarr store (a folder); give a new path")
    try:
        path.resolve().parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DatasetError(f"{path}: cannot create its folder ({exc.strerror})") from exc
    where = path.resolve() if path.is_dir() else path.resolve().parent  # a store resumed, or made
    try:  # a read-only mount failed later, naming the store's scratch folder
        probe_writable(where)
    except OSError as exc:
        raise DatasetError(f"{path}: cannot write in {where} ({exc.strerror})") from exc
    if not path.exists():  # a new store: it must fit (a resume writes what its pending samples need)
        _check_room(spec, path, where)


def _check_room(spec: DatasetSpec, path: Path, where: Path) -> None:
    """Refuse a new store that would not fit on its disk (:func:`store_bytes`, an upper
    estimate): a 10-million-sample spec started computing toward 200 GB on a disk with 78 GB
    free, to stop with a full disk hours later."""
    need = store_bytes(spec)
    free = shutil.disk_usage(where).free
    if need > free:
        raise DatasetError(f"{path}: the store would take up to {need / 1e9:.3g} GB ({spec.samples} "
                           f"samples, {need / spec.samples / 1e6:.3g} MB each) and its disk has "
                           f"{free / 1e9:.3g} GB free: make fewer samples or a coarser grid, or "
                           "give a path on a larger disk")


def _run(client, path: str, spec: DatasetSpec, device: str, pending: np.ndarray,
         ideal_pending: np.ndarray, writer: zstore.Writer, report: SampleReport, skipped: int,
         failures: list, ideal_failures: list) -> None:
    """Submit the tasks and count their outcomes as they complete."""
    from distributed import KilledWorker, as_completed

    token = uuid.uuid4().hex[:10]
    fp = spec.fingerprint
    jobs: dict[str, tuple[str, int]] = {}
    futures = []
    for f in ideal_pending.tolist():
        key = f"raysim-ideal-{token}-{f}"
        futures.append(client.submit(run_ideal, path, fp, f, device, key=key, priority=10))
        jobs[key] = ("ideal", f)
    indices = pending.tolist()
    if indices:
        keys = [f"raysim-sample-{token}-{i}" for i in indices]
        n = len(indices)
        futures += client.map(run_sample, [path] * n, [fp] * n, indices, [device] * n, key=keys)
        jobs.update({k: ("sample", i) for k, i in zip(keys, indices, strict=True)})
    done = skipped
    for future in as_completed(futures, loop=client.loop):
        kind, index = jobs[future.key]
        try:
            out = future.result()
        except Exception as exc:  # raised outside the task's own guard
            if isinstance(exc, KilledWorker):
                reason = f"its worker died each time it ran it ({type(exc).__name__})"
            else:
                reason = f"the task could not run ({type(exc).__name__}: {' '.join(str(exc).split())})"
            if kind == "sample":
                writer.failed(index, reason)
            else:
                writer.ideal(index, None, reason)
            out = {"ok": False, "error": reason}
        future.release()
        if kind == "ideal":
            if not out["ok"]:
                ideal_failures.append((index, out["error"]))
            continue
        if out["ok"]:
            done += 1
        else:
            failures.append((index, out["error"]))
        report(done, len(failures), spec.samples)


#: errno values of a write the disk (or the user's quota) had no room for
FULL_DISK = (errno.ENOSPC, errno.EDQUOT)


def _full_disk_line(path: str, removed: bool) -> str:
    """What a run stopped by a full disk says: the store, and how to go on."""
    if removed:
        return (f"{path}: no space left on the device before any sample was finished; the store "
                "was removed: free space and run the same command again")
    return (f"{path}: no space left on the device; the finished samples are kept and checked: "
            "free space and run the same command with --resume to complete the store")


def _existing_store(path: str, spec: DatasetSpec, resume: bool):
    """The store at ``path`` opened for ``spec`` when it exists (it must, with ``resume``, be
    one made by the same spec), else None."""
    if not zstore.exists(path):
        return None
    if not resume:
        raise DatasetError(f"{path}: already exists; add --resume to complete it, or give a new path")
    return zstore.open_checked(path, spec)


def _prepare_workers(client, threads: int, device: str) -> None:
    """Register the dataset's worker plugin (Warp threads and device, the per-worker caches)."""
    try:
        client.register_plugin(DatasetWorkerPlugin(threads, device))
    except Exception as exc:  # e.g. a device the workers lack, Warp failing to load
        raise DatasetError(f"the Dask workers could not be prepared ({type(exc).__name__}: "
                           f"{' '.join(str(exc).split())})") from exc


def _store_path(store: str | Path) -> str:
    text = str(store)
    return text if "://" in text else str(Path(text).expanduser().resolve())
