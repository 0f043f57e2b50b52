"""Reading a dataset back: the whole store as a lazy xarray Dataset, one sample as a FieldMap,
and any sample regenerated alone from its spec (no store, no cluster).

:func:`open_dataset` checks the store's coordinates, seeds, split and attributes against the
checksums it recorded (:func:`raysim.dataset.integrity.check_static`); its sample arrays are
lazy and unverified. :func:`sample_fieldmap` reads its sample from the store and verifies it
against its checksum (:class:`~raysim.dataset.integrity.CorruptSampleError` if it fails).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

from raysim.dataset import integrity
from raysim.dataset.sampling import draw_sample
from raysim.dataset.spec import DatasetError, DatasetSpec
from raysim.dataset.store import open_readonly

SOURCES = {"clean": "intensity", "measured": "intensity_measured"}  # source -> store variable


def open_dataset(store: str | Path) -> xr.Dataset:
    """The store as an ``xarray.Dataset`` backed by lazy Dask arrays (nothing is loaded).

    Use only samples with ``status == 1``; ``split == 1`` marks the validation samples. The
    coordinates, ``seed``, ``split`` and the attributes are checked against the checksums the
    store recorded (CorruptStoreError); a per-item record (``status``, ``seconds``, ...) whose
    chunk does not decode raises CorruptStoreError when read; the per-sample data arrays are read
    unverified (use :func:`sample_fieldmap` or :class:`~raysim.dataset.loader.Loader`, which
    verify them).
    """
    path = str(store)
    group = open_readonly(path)
    integrity.check_static(group, path)  # one clear line if not trusted
    # the sample arrays opened first: a missing or garbled one is named (xarray would raise a
    # raw JSONDecodeError, or silently leave a variable out)
    integrity.open_arrays(group, path, integrity.data_names(group, path))
    try:
        ds = xr.open_zarr(path, consolidated=False)
    except Exception as exc:
        raise integrity.CorruptStoreError(f"{path}: the metadata of one of its arrays cannot be read "
                                          f"({type(exc).__name__}); {integrity.resume_hint(path)}") from exc
    names = [v for v in ds.data_vars if v.endswith(("_term_n", "_term_m"))]
    return _guard_records(ds.set_coords(names), group, path)


def _guard_records(ds: xr.Dataset, group, path: str) -> xr.Dataset:
    """``ds`` with its record arrays (:data:`~raysim.dataset.integrity.RECORDS`) read through
    :class:`~raysim.dataset.integrity.GuardedRecords`: a damaged chunk of one (which no
    checksum covers) raises CorruptStoreError at ``.values``. xarray decodes nothing of them
    (no fill value, offset or scale is applied to these types), so the values are the same."""
    import dask.array as da

    for name in integrity.RECORDS:
        if name in ds.variables:
            lazy = ds[name].data
            guarded = da.from_array(integrity.GuardedRecords(group[name], path, name),
                                    chunks=lazy.chunks, name=False, asarray=False, fancy=False)
            ds[name] = ds[name].copy(data=guarded)
    return ds


def sample_fieldmap(ds: xr.Dataset, index: int, source: str = "clean") -> xr.Dataset:
    """Sample ``index`` of a dataset opened by :func:`open_dataset` as a FieldMap (see
    :mod:`raysim.maps.fieldmap`); ``source`` ``measured`` takes its ``intensity_measured`` (a
    store with measurement effects).

    The sample's data and its frequency's ideal intensity are read from the store and verified
    against their checksums: one that fails raises
    :class:`~raysim.dataset.integrity.CorruptSampleError` naming the store and the sample.
    """
    from raysim.maps.fieldmap import fieldmap, grid_of

    variable = _intensity_variable(ds, source)
    path, group = _store_of(ds)
    sample = ds.isel(sample=index)
    number = int(sample["sample"].values)  # the sample's index in the store
    names = integrity.data_names(group, path)
    values = integrity.read_verified(integrity.open_arrays(group, path, names), path, [number], names,
                                     integrity.binding(group.attrs))
    frequency = float(values["frequency_hz"][0])
    ideal = integrity.ideal_of(path, *integrity.read_ideals(group, path), frequency)
    from raysim.scene import scene_of

    scene = scene_of(ds.attrs)  # its probe read the samples (raysim.maps.probe)
    attrs = {"dataset": ds.attrs.get("name", ""), "sample": number,
             "seed": str(int(sample["seed"].values)), "deformation_rms": float(values["rms"][0]),
             "dataset_intensity": variable, **(scene.probe.attrs() if scene is not None else {})}
    return fieldmap(grid_of(ds), values[variable][0], ideal,
                    focal_length=ds.attrs["focal_length"], diameter=ds.attrs["diameter"],
                    frequency_hz=frequency, method=ds.attrs["method"], sampling=ds.attrs["sampling"],
                    scene=ds.attrs.get("scene"), attrs=attrs)


def _store_of(ds: xr.Dataset):
    """(path, read-only group) of the store ``ds`` was opened from."""
    path = ds.encoding.get("source")
    if not path:
        raise DatasetError("sample_fieldmap reads a dataset opened by raysim.dataset.open_dataset "
                           "(this one names no store to verify its sample against)")
    return str(path), open_readonly(str(path))


def _intensity_variable(ds: xr.Dataset, source: str) -> str:
    if source not in SOURCES:
        raise DatasetError(f"unknown intensity source {source!r}: use one of {', '.join(SOURCES)}")
    name = SOURCES[source]
    if name not in ds.variables:
        raise DatasetError("this store has no measured intensity (its spec has no [measurement] table)")
    return name


def sample_intensity(spec: DatasetSpec, index: int, device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
    """Regenerate sample ``index`` alone, in this process: (deformation map (m), intensity)."""
    from raysim.dataset.engine import simulate_sample

    draw = draw_sample(spec, index)
    return spec.grid.evaluate(draw.deformation), simulate_sample(spec, draw.deformation,
                                                                  draw.frequency_index, device)


def sample_measured(spec: DatasetSpec, index: int, device: str = "cpu") -> np.ndarray:
    """Regenerate sample ``index``'s measured intensity alone (a spec with measurement effects)."""
    from raysim.dataset.engine import ideal_intensity

    if spec.measurement is None:
        raise DatasetError("the spec has no [measurement] table")
    draw = draw_sample(spec, index)
    _, clean = sample_intensity(spec, index, device)
    return draw.measured(clean, ideal_intensity(spec, draw.frequency_index, device), spec)
