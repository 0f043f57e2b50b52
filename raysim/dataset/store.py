"""The Zarr store of a dataset: its layout, creation, checks and per-sample writes.

Layout (Zarr format 3, every array with ``dimension_names`` and a ``units`` attribute, so
``xarray.open_zarr`` reads it as one Dataset):

- coordinates ``sample``, ``theta``, ``phi`` (rad, cell centres as in a FieldMap), ``x``,
  ``y`` (m, the N x N cell-centred aperture grid), ``frequency`` (Hz), and per model its own
  (``<model>_term_n``/``_m``, ``panel``);
- ``intensity(sample, theta, phi)``: |E|^2 relative to the incident wave, one chunk per
  sample; with measurement effects also ``intensity_measured`` (the same with the sample's
  effects, NaN where a point is missing) and the effects' values ``measure_*``;
  ``intensity_ideal(frequency, theta, phi)``, the ideal paraboloid once per frequency;
- ``deformation(sample, y, x)``: delta (m), NaN outside the aperture r < D/2;
- ``seed``, ``split`` (0 train, 1 validation), ``frequency_hz``, ``rms``, ``peak_to_peak``
  and every model's parameters per sample; ``status`` (0 pending, 1 done, 2 failed),
  ``error`` (the reason of a failure), ``seconds``, ``cpu_seconds`` and ``finished`` (UNIX
  time) per sample.

Every array a worker writes is chunked one sample per chunk, so workers never share a chunk.
A sample's ``status`` is written after all its data and its ``checksum`` (SHA-256 of its
index and seed and of every per-sample data array, :func:`sample_checksum`): it is the
completion marker, and ``resume`` verifies every done sample against its checksum first
(:func:`verify`; a chunk that does not decode, or was removed and reads as the fill value,
or a sample's chunks moved to another's place, fails), making the ones that fail pending
again (:func:`reset`). ``intensity_ideal`` has ``ideal_checksum`` likewise. The
arrays written at creation and the attributes are checked against the spec on resume, and
against the ``static_checksums`` attribute by readers (:mod:`raysim.dataset.integrity`).
Attributes hold the spec and scene text, the spec's fingerprint, the FieldMap
attributes (``focal_length``, ``diameter``, ``sphere_radius``, ``method``, ``sampling``, the
sphere's edges) and the versions of the packages that made the store.
"""

from __future__ import annotations

import math
import os
import platform
import shutil
import time
import uuid
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
import zarr

from raysim.dataset.integrity import (
    BOOKKEEPING,
    CHECKED_ATTRS,
    binding,
    checksum,
    ideal_checksum,
    listed_data_names,
    record_static,
    same_toml,
    static_arrays,
)
from raysim.dataset.integrity import sample_checksum as integrity_sample_checksum
from raysim.dataset.sampling import sample_seed
from raysim.dataset.spec import DatasetError, DatasetSpec
from raysim.dataset.store_layout import FORMAT, READ_FORMATS, ArraySpec, layout
from raysim.distributed.inputs import changed_inputs
from raysim.version import VERSION_ATTR, __version__

PENDING, DONE, FAILED = 0, 1, 2
_BATCH = 256  # samples read at once while verifying
_PACKAGES = ("numpy", "scipy", "warp-lang", "dask", "distributed", "zarr", "xarray")
#: the versions a sample's values depend on (its kernels, splines and random draws): a store is
#: resumed, and a worker writes into it, only with these as the store recorded them, so that
#: no store holds samples of two of them (a store that did not record one is not held to it)
_VALUES_DEPEND_ON = (VERSION_ATTR, "version_numpy", "version_scipy", "version_warp")


def versions() -> dict[str, str]:
    """raysim's version (under :data:`~raysim.version.VERSION_ATTR`, as every output records
    it) and ``version_<package>`` of Python and the packages a sample depends on."""
    out = {VERSION_ATTR: __version__, "version_python": platform.python_version()}
    for name in _PACKAGES:
        try:
            out[f"version_{name.split('-')[0]}"] = metadata.version(name)
        except metadata.PackageNotFoundError:  # pragma: no cover - all are dependencies
            out[f"version_{name.split('-')[0]}"] = "absent"
    return out


def version_changes(attrs: Any) -> list[str]:
    """What of :data:`_VALUES_DEPEND_ON` differs between a store's attributes and this process,
    as "numpy 2.3.1 -> 2.4.0" (raysim's as "raysim ..."); empty when nothing does."""
    now = versions()
    return [f"{'raysim' if key == VERSION_ATTR else key.removeprefix('version_')} "
            f"{attrs[key]} -> {now[key]}"
            for key in _VALUES_DEPEND_ON if key in attrs and str(attrs[key]) != now[key]]


def refuse_other_versions(path: str, attrs: Any) -> None:
    """Refuse (DatasetError) to add samples to a store made with other versions of what they
    depend on: its samples would differ from the others in their last bits, or more."""
    changes = version_changes(attrs)
    if changes:
        raise DatasetError(f"{path}: made with other versions of what its samples depend on "
                           f"({', '.join(changes)}), so a resume here would mix samples of both: "
                           "finish it where it was made, or make the dataset again at a new "
                           "store path")


def create(path: str, spec: DatasetSpec) -> zarr.Group:
    """A new store at ``path`` (which must not exist) with its coordinates, seeds and split.

    A local store is built in a hidden sibling folder ``.NAME.HOST-PID-XXXX.tmp`` and renamed
    into place, so a run killed while creating it leaves no half-made store that ``resume``
    would have to trust; what such a run left is removed here once its process is gone
    (:func:`remove_leftovers`).
    """
    if "://" in path:
        return _fill(zarr.open_group(path, mode="w-", attributes=_attributes(spec)), spec)
    from raysim.files import writer_prefix

    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    remove_leftovers(path)
    scratch = target.parent / f"{writer_prefix(target)}{uuid.uuid4().hex[:8]}.tmp"
    try:
        _fill(zarr.open_group(str(scratch), mode="w-", attributes=_attributes(spec)), spec)
        os.rename(scratch, target)  # fails if the target appeared meanwhile
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return zarr.open_group(path, mode="r+")


def remove_leftovers(path: str) -> None:
    """Remove what killed runs left beside the local store ``path``: their scratch folders
    ``.NAME.HOST-PID-XXXX.tmp`` once process PID of this host is gone
    (:func:`raysim.files.remove_stale`; a run still creating the store keeps its own), and
    the ``.NAME.XXXX.creating`` folders of older raysims, which name no process, once a day old."""
    if "://" in path:
        return
    from raysim.files import FOREIGN_STALE_S, remove_stale

    target = Path(path)
    remove_stale(target)
    if not target.parent.is_dir():
        return
    for stale in target.parent.glob(f".{target.name}.*.creating"):
        try:
            old = time.time() - stale.lstat().st_mtime >= FOREIGN_STALE_S
        except OSError:
            continue
        if old and stale.is_dir() and not stale.is_symlink():
            shutil.rmtree(stale, ignore_errors=True)


def _fill(group: zarr.Group, spec: DatasetSpec) -> zarr.Group:
    for name, array in layout(spec).items():
        group.create_array(name, shape=array.shape, chunks=array.chunks, dtype=array.dtype,
                           fill_value=array.fill, dimension_names=array.dims, attributes=array.attrs)
    for name, values in static_arrays(spec).items():  # what a resume checks them against
        group[name][...] = values
    record_static(group, spec)
    return group


def open_checked(path: str, spec: DatasetSpec) -> zarr.Group:
    """Open an existing store for writing; refuse one another spec (or no raysim) made."""
    try:
        group = zarr.open_group(path, mode="r+")
    except (FileNotFoundError, ValueError, KeyError) as exc:
        raise DatasetError(f"{path}: not a Zarr store ({exc.__class__.__name__})") from exc
    attrs = group.attrs
    check_format(path, attrs)
    if attrs.get("fingerprint") != spec.fingerprint:
        _refuse_changed_inputs(path, attrs, spec)
        raise DatasetError(f"{path} was made by a different spec (dataset "
                           f"{attrs.get('name')!r}, fingerprint {str(attrs.get('fingerprint'))[:12]}, "
                           f"this spec {spec.fingerprint[:12]}): use a new store path")
    refuse_other_versions(path, attrs)
    return group


def _refuse_changed_inputs(path: str, attrs: Any, spec: DatasetSpec) -> None:
    """Name the file when what differs from the store's fingerprint is a file the scene names
    (its results would mix the file's two versions); return when the spec itself differs."""
    if not same_toml(attrs.get("spec"), spec.text) or not same_toml(attrs.get("scene"), spec.scene_text):
        return
    recorded, current = attrs.get("inputs"), dict(spec.inputs)
    if recorded is None and current:
        raise DatasetError(f"{path}: made by an older raysim that did not record the contents of the "
                           f"files its scene names ({', '.join(current)}), so a resume could mix "
                           "two versions of them: make the dataset again at a new store path")
    changed = changed_inputs(recorded, current)
    if changed:
        raise DatasetError(f"{path}: {changed[0]}, a file its scene names, is not the one the store "
                           "was made from (its SHA-256 differs): restore that file, or make the "
                           "dataset again at a new store path")


def open_readonly(path: str) -> zarr.Group:
    """Open a dataset store for reading (any spec)."""
    try:
        group = zarr.open_group(path, mode="r")
    except (FileNotFoundError, ValueError, KeyError) as exc:
        raise DatasetError(f"{path}: not a Zarr store ({exc.__class__.__name__})") from exc
    check_format(path, group.attrs)
    return group


def check_format(path: str, attrs: Any) -> None:
    """Refuse (DatasetError, one line) a store that is not of this raysim's format: another
    raysim's (older: its checksums do not record which sample they are, so they cannot be
    verified as this one does) or none."""
    made = attrs.get("raysim_dataset_format")
    if made in READ_FORMATS and not isinstance(made, bool):
        return
    if isinstance(made, int) and not isinstance(made, bool) and made >= 1:
        which = "an older" if made < FORMAT else "a newer"
        raise DatasetError(f"{path}: made by {which} raysim (dataset store format {made}, this raysim "
                           f"reads formats {', '.join(map(str, READ_FORMATS))}): make the dataset "
                           "again at a new store path")
    raise DatasetError(f"{path}: not a raysim dataset store (format {FORMAT})")


def status(group: zarr.Group) -> np.ndarray:
    """Per-sample status (PENDING, DONE, FAILED); an unreadable marker counts as pending."""
    return _markers(group["status"])[0]


def ideal_status(group: zarr.Group) -> np.ndarray:
    """Status of the ideal intensity of each frequency; an unreadable marker counts as pending
    (its ideal is computed again, as a sample's is)."""
    return _markers(group["ideal_status"])[0]


def _markers(arr: Any) -> tuple[np.ndarray, np.ndarray]:
    """(every marker of ``arr``, which of them do not decode): one read when all decode; else
    one by one, an unreadable one (torn by a kill mid-write, garbled) read as PENDING."""
    try:
        values = np.asarray(arr[...])
        return values, np.zeros(values.shape, dtype=bool)
    except Exception:
        values = np.zeros(arr.shape[0], dtype=np.int8)
        unreadable = np.zeros(arr.shape[0], dtype=bool)
        for i in range(arr.shape[0]):
            try:
                values[i] = arr[i]
            except Exception:
                values[i], unreadable[i] = PENDING, True
        return values, unreadable


def data_names(group: zarr.Group) -> list[str]:
    """The per-sample data arrays present in a store (one sample per chunk, not bookkeeping),
    sorted. A resume takes them from the spec instead (:func:`raysim.dataset.integrity.spec_data_names`)."""
    return listed_data_names(group)


def sample_checksum(group: zarr.Group, index: int, names: list[str] | None = None) -> str:
    """The checksum of sample ``index`` as stored (its data arrays and seed read back)."""
    names = data_names(group) if names is None else names
    values = {name: np.asarray(group[name][index]) for name in names}
    return integrity_sample_checksum(values, index, int(group["seed"][index]), binding(group.attrs))


def require_checksums(group: zarr.Group, path: str) -> None:
    """Refuse (DatasetError) a store that records no checksums (made by an older raysim)."""
    if "checksum" not in group or "ideal_checksum" not in group:
        raise DatasetError(f"{path}: records no checksums (made by an older raysim), so its samples "
                           "cannot be verified: make it again at a new store path")


def verify(group: zarr.Group, path: str, names: list[str],
           seeds: np.ndarray | None = None) -> tuple[list[int], list[int]]:
    """The samples, and the ideal intensities, to make pending again before a resume: the done
    ones whose stored data do not match their checksums (or do not decode), and the ones whose
    completion marker was lost (its chunk unreadable, or removed while the item's checksum,
    written just before it, is there). ``names``: the per-sample data arrays, as the spec's
    layout gives them; ``seeds``: every sample's seed, as the spec gives them (default: the
    store's). A store that records no checksums, or whose bookkeeping cannot be read, is
    refused (DatasetError, one line naming it)."""
    try:
        require_checksums(group, path)
        marks, unreadable = _markers(group["status"])
        sums = _read_each(group["checksum"], np.arange(len(marks)))
        done = np.flatnonzero(marks == DONE)
        seeds = np.asarray(group["seed"][...]) if seeds is None else seeds
        arrays = {name: group[name] for name in names}
        ideal_marks, ideal_unreadable = _markers(group["ideal_status"])
        ideal_sums = _read_each(group["ideal_checksum"], np.arange(len(ideal_marks)))
        ideal_done = np.flatnonzero(ideal_marks == DONE)
        ideal_values = _read_each(group["intensity_ideal"], ideal_done)
        bound = binding(group.attrs)
    except DatasetError:
        raise
    except Exception as exc:
        raise DatasetError(f"{path}: its bookkeeping cannot be read ({type(exc).__name__}); "
                           "make it again at a new store path") from exc
    bad = []
    for lo in range(0, len(done), _BATCH):
        batch = done[lo:lo + _BATCH]
        read = {name: _read_each(arr, batch) for name, arr in arrays.items()}
        for k, index in enumerate(batch.tolist()):
            values = {name: read[name][k] for name in names}
            if any(v is None for v in values.values()) or \
                    sums[index] != integrity_sample_checksum(values, index, int(seeds[index]), bound):
                bad.append(index)
    ideal_bad = [int(f) for f, v in zip(ideal_done, ideal_values, strict=True)
                 if v is None or ideal_sums[f] != ideal_checksum(v, int(f), bound)]
    return (sorted([*bad, *_lost_markers(marks, unreadable, sums)]),
            sorted([*ideal_bad, *_lost_markers(ideal_marks, ideal_unreadable, ideal_sums)]))


def _lost_markers(marks: np.ndarray, unreadable: np.ndarray, sums: list[Any]) -> list[int]:
    """The pending items whose marker did not decode, or whose checksum is there although their
    marker reads as pending (its chunk removed: a worker writes the checksum just before the
    marker, and a reset clears the marker first, so only that narrow window of a kill leaves
    the same): finished items whose marker was lost."""
    return [i for i in np.flatnonzero(marks == PENDING).tolist()
            if unreadable[i] or (sums[i] is not None and str(sums[i]) != "")]


#: per-item bookkeeping a done item keeps but no checksum covers (how long, when, why it failed),
#: with the fill value that a resume writes over a chunk of it that does not decode
RUN_RECORDS = {"status": ("error", "seconds", "cpu_seconds", "finished"), "ideal_status": ("ideal_error",)}


def clear_unreadable_records(group: zarr.Group) -> dict[str, int]:
    """Rewrite, as the array's fill value, every chunk of :data:`RUN_RECORDS` of a done item
    that does not decode (a done item's ``error`` is empty, its lost times unknown: NaN), so
    that every reader can read the store again; the items' data, which their checksums vouch
    for, are kept. Returns array name -> how many chunks were rewritten (the nonzero ones).
    Pending items need nothing: their task rewrites their records."""
    out = {}
    for marker, names in RUN_RECORDS.items():
        done = np.flatnonzero(_markers(group[marker])[0] == DONE)
        for name in names:
            arr = group[name]
            lost = [int(i) for i, v in zip(done, _read_each(arr, done), strict=True) if v is None]
            for i in lost:
                arr[i] = arr.metadata.fill_value
            if lost:
                out[name] = len(lost)
    return out


def _read_each(arr: Any, indices: np.ndarray) -> list[Any]:
    """``arr[i]`` for each index (None where its chunk does not decode): one read of the
    range when it decodes, else one per index."""
    if not len(indices):
        return []
    lo, hi = int(indices[0]), int(indices[-1]) + 1
    try:
        block = np.asarray(arr[lo:hi])
        return [np.asarray(block[i - lo]) for i in indices.tolist()]
    except Exception:
        out: list[Any] = []
        for i in indices.tolist():
            try:
                out.append(np.asarray(arr[i]))
            except Exception:
                out.append(None)
        return out


def reset(group: zarr.Group, samples: Iterable[int], ideals: Iterable[int], names: list[str]) -> None:
    """Make samples and ideal intensities pending again: the marker first, then their data
    chunks (``names``, the spec's) written as the fill value (which removes them), so that a
    recomputation gives the store an uninterrupted run would have."""
    names = [*names, "checksum"]
    for index in samples:
        group["status"][index] = PENDING
        for name in names:
            arr = group[name]
            arr[index] = arr.metadata.fill_value
    for f in ideals:
        group["ideal_status"][f] = PENDING
        for name in ("intensity_ideal", "ideal_checksum"):
            arr = group[name]
            arr[f] = arr.metadata.fill_value


@dataclass
class Writer:
    """Writes one process's samples into an open store (array handles cached)."""

    group: zarr.Group
    names: list[str] | None = None  # the per-sample data arrays (default: those in the store)
    spec_seed: int | None = None  # the spec's seed, whence each sample's (default: the store's)

    def __post_init__(self) -> None:
        self._arrays: dict[str, Any] = {}
        self.bound = binding(self.group.attrs)  # what its checksums hash (its format's rule)

    def __getitem__(self, name: str) -> Any:
        if name not in self._arrays:
            self._arrays[name] = self.group[name]
        return self._arrays[name]

    def _put(self, index: int, items: dict[str, Any]) -> None:
        """Write ``items`` (array name -> sample ``index``'s value) all at once: Zarr's own
        event loop runs the chunk writes concurrently (one after the other without it)."""
        arrays = [(self[name], value) for name, value in items.items()]
        if all(hasattr(a, "_async_array") for a, _ in arrays):
            import asyncio

            from zarr.core.sync import sync

            async def write() -> None:
                await asyncio.gather(*(a._async_array.setitem(index, v) for a, v in arrays))

            sync(write())
            return
        for array, value in arrays:  # pragma: no cover - a Zarr without the async layer
            array[index] = value

    def params(self, index: int, params: dict[str, Any], frequency_hz: float,
               deformation: np.ndarray) -> None:
        """The sample's drawn parameters, frequency and deformation map (m)."""
        values = deformation[np.isfinite(deformation)]
        self._put(index, {
            **params, "frequency_hz": frequency_hz, "deformation": deformation,
            "rms": float(np.sqrt(np.mean(values**2))) if values.size else math.nan,
            "peak_to_peak": float(np.ptp(values)) if values.size else math.nan})

    def done(self, index: int, intensity: np.ndarray, seconds: float, cpu_seconds: float = math.nan,
             measured: np.ndarray | None = None) -> None:
        """The sample's intensity (and its measured one), then its completion marker (last)."""
        items = {"intensity": intensity, "seconds": seconds, "cpu_seconds": cpu_seconds, "error": "",
                 "finished": time.time()}
        if measured is not None:
            items["intensity_measured"] = measured
        self._put(index, items)
        if self.names is None:  # the same for every sample of the store
            self.names = data_names(self.group)
        values = {name: np.asarray(self[name][index]) for name in self.names}
        self["checksum"][index] = integrity_sample_checksum(values, index, self._seed(index), self.bound)
        self["status"][index] = DONE

    def _seed(self, index: int) -> int:
        """Sample ``index``'s seed: from the spec's when known (no read of the store's array)."""
        if self.spec_seed is not None:
            return sample_seed(self.spec_seed, index)
        return int(self["seed"][index])

    def failed(self, index: int, reason: str, seconds: float = math.nan) -> None:
        """Mark the sample failed with a one-line ``reason``."""
        self["error"][index] = " ".join(reason.split())[:500]
        self["seconds"][index] = seconds
        self["finished"][index] = time.time()
        self["status"][index] = FAILED

    def ideal(self, f_index: int, intensity: np.ndarray | None, reason: str = "") -> None:
        """The ideal intensity of frequency ``f_index`` (or its failure), then its marker."""
        if intensity is not None:
            self["intensity_ideal"][f_index] = intensity
            stored = np.asarray(self["intensity_ideal"][f_index])
            self["ideal_checksum"][f_index] = ideal_checksum(stored, f_index, self.bound)
            self["ideal_status"][f_index] = DONE
        else:
            self["ideal_error"][f_index] = " ".join(reason.split())[:500]
            self["ideal_status"][f_index] = FAILED


def _attributes(spec: DatasetSpec) -> dict[str, Any]:
    grid = spec.scene.sphere
    return {
        "raysim_dataset_format": FORMAT,
        "name": spec.name,
        "description": spec.description,
        "fingerprint": spec.fingerprint,
        "spec": spec.text,
        "spec_source": spec.source,
        "spec_base": str(spec.base),
        "scene": spec.scene_text,
        "inputs": dict(spec.inputs),
        "samples": spec.samples,
        "seed": spec.seed,
        "method": spec.method,
        "radiator": spec.radiator if spec.method in ("po", "po+ptd") else "none",
        "radiator_tol": spec.radiator_tol,
        "sampling": "cell_mean" if spec.method == "go" else "centre",
        "focal_length": spec.scene.F,
        "diameter": spec.scene.D,
        "sphere_radius": float(grid.radius),
        "theta_min": float(grid.theta_min),
        "theta_max": float(grid.theta_max),
        "phi_min": float(grid.phi_min),
        "phi_max": float(grid.phi_max),
        "validation_fraction": spec.validation_fraction,
        "models": ", ".join(f"{m.name} ({m.kind})" for m in spec.models) or "none",
        "measurement": "intensity_measured: intensity with the measure_* effects of each sample "
                       "(raysim.dataset.effects)" if spec.measurement is not None else "none",
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "status_meanings": "0 pending, 1 done, 2 failed",
        **versions(),
    }


def spec_attributes(spec: DatasetSpec) -> dict[str, Any]:
    """The root attributes that are functions of the spec's content alone (what a resume
    checks, :data:`raysim.dataset.integrity.CHECKED_ATTRS`)."""
    attrs = _attributes(spec)
    return {k: attrs[k] for k in CHECKED_ATTRS}


def exists(path: str) -> bool:
    """Whether something is at a local store path (remote URLs: let Zarr decide)."""
    return "://" not in path and Path(path).exists()


__all__ = ["BOOKKEEPING", "DONE", "FAILED", "PENDING", "RUN_RECORDS", "ArraySpec", "Writer", "checksum",
           "clear_unreadable_records", "create", "data_names", "exists", "ideal_status", "open_checked",
           "open_readonly", "remove_leftovers", "require_checksums", "reset", "sample_checksum",
           "spec_attributes", "status", "verify", "versions"]
