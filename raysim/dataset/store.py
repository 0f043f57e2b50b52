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
A sample's ``status`` is written after all its data: it is the completion marker ``resume``
trusts. Attributes hold the spec and scene text, the spec's fingerprint, the FieldMap
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
from dataclasses import dataclass
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
import zarr

from raysim.dataset.spec import DatasetError, DatasetSpec
from raysim.dataset.store_layout import FORMAT, ArraySpec, layout
from raysim.version import VERSION_ATTR, __version__

PENDING, DONE, FAILED = 0, 1, 2
_PACKAGES = ("numpy", "warp-lang", "dask", "distributed", "zarr", "xarray")


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


def create(path: str, spec: DatasetSpec) -> zarr.Group:
    """A new store at ``path`` (which must not exist) with its coordinates, seeds and split.

    A local store is built in a hidden sibling folder and renamed into place, so a run killed
    while creating it leaves no half-made store that ``resume`` would have to trust.
    """
    if "://" in path:
        return _fill(zarr.open_group(path, mode="w-", attributes=_attributes(spec)), spec)
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    scratch = target.parent / f".{target.name}.{uuid.uuid4().hex[:8]}.creating"
    try:
        _fill(zarr.open_group(str(scratch), mode="w-", attributes=_attributes(spec)), spec)
        os.rename(scratch, target)  # fails if the target appeared meanwhile
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return zarr.open_group(path, mode="r+")


def _fill(group: zarr.Group, spec: DatasetSpec) -> zarr.Group:
    from raysim.dataset.sampling import sample_seed, validation_mask

    for name, array in layout(spec).items():
        arr = group.create_array(name, shape=array.shape, chunks=array.chunks, dtype=array.dtype,
                                 fill_value=array.fill, dimension_names=array.dims,
                                 attributes=array.attrs)
        if array.values is not None:
            arr[...] = array.values
    group["seed"][...] = np.array([sample_seed(spec.seed, i) for i in range(spec.samples)],
                                  dtype=np.uint64)
    group["split"][...] = validation_mask(spec).astype(np.int8)
    return group


def open_checked(path: str, spec: DatasetSpec) -> zarr.Group:
    """Open an existing store for writing; refuse one another spec (or no raysim) made."""
    try:
        group = zarr.open_group(path, mode="r+")
    except (FileNotFoundError, ValueError, KeyError) as exc:
        raise DatasetError(f"{path}: not a Zarr store ({exc.__class__.__name__})") from exc
    attrs = group.attrs
    if attrs.get("raysim_dataset_format") != FORMAT:
        raise DatasetError(f"{path}: not a raysim dataset store (format {FORMAT})")
    if attrs.get("fingerprint") != spec.fingerprint:
        raise DatasetError(f"{path} was made by a different spec (dataset "
                           f"{attrs.get('name')!r}, fingerprint {str(attrs.get('fingerprint'))[:12]}, "
                           f"this spec {spec.fingerprint[:12]}): use a new store path")
    return group


def open_readonly(path: str) -> zarr.Group:
    """Open a dataset store for reading (any spec)."""
    try:
        group = zarr.open_group(path, mode="r")
    except (FileNotFoundError, ValueError, KeyError) as exc:
        raise DatasetError(f"{path}: not a Zarr store ({exc.__class__.__name__})") from exc
    if group.attrs.get("raysim_dataset_format") != FORMAT:
        raise DatasetError(f"{path}: not a raysim dataset store")
    return group


def status(group: zarr.Group) -> np.ndarray:
    """Per-sample status (PENDING, DONE, FAILED); an unreadable marker counts as pending."""
    try:
        return np.asarray(group["status"][...])
    except Exception:  # a marker torn by a kill mid-write: read them one by one
        arr = group["status"]
        out = np.zeros(arr.shape[0], dtype=np.int8)
        for i in range(arr.shape[0]):
            try:
                out[i] = arr[i]
            except Exception:
                out[i] = PENDING
        return out


def ideal_status(group: zarr.Group) -> np.ndarray:
    """Status of the ideal intensity of each frequency."""
    return np.asarray(group["ideal_status"][...])


@dataclass
class Writer:
    """Writes one process's samples into an open store (array handles cached)."""

    group: zarr.Group

    def __post_init__(self) -> None:
        self._arrays: dict[str, Any] = {}

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
        self["status"][index] = DONE

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
        "samples": spec.samples,
        "seed": spec.seed,
        "method": spec.method,
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


def exists(path: str) -> bool:
    """Whether something is at a local store path (remote URLs: let Zarr decide)."""
    return "://" not in path and Path(path).exists()


__all__ = ["DONE", "FAILED", "PENDING", "ArraySpec", "Writer", "create", "exists", "ideal_status",
           "open_checked", "open_readonly", "status", "versions"]
