"""What a dataset store holds besides its samples, checked: its arrays' presence and layout,
the arrays written once at creation and the root attributes; and samples read back verified.

The arrays written when a store is created (the coordinates, ``seed``, ``split``) and the root
attributes that describe its data (``diameter``, the sphere's edges, ...) are deterministic
functions of the spec. Two checks use that:

- a resume (:func:`check_store`, then :func:`repair`) refuses a store one of whose arrays has
  another shape, chunks or type than the spec's layout gives, rewrites the metadata of an array
  whose ``zarr.json`` is missing or unreadable as the layout makes it (its chunks kept, then
  verified: a good sample's data are never reset on the word of a listing), and rewrites from
  the spec whatever of the creation-time arrays and attributes no longer matches it (nothing
  computed is lost: they are the spec's);
- readers (:func:`check_static`, :func:`read_verified`, :func:`read_ideals`), which have no
  spec, compare the creation-time arrays and attributes with the SHA-256 recorded in the
  store's ``static_checksums`` attribute when it was made (or last resumed), and every sample
  they return with its own ``checksum``.

Each failure is one line naming the store: :class:`CorruptStoreError` and
:class:`CorruptSampleError` (both :class:`~raysim.dataset.spec.DatasetError`) say to resume.
"""

from __future__ import annotations

import hashlib
import json
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import zarr

from raysim.dataset.spec import DatasetError, DatasetSpec
from raysim.dataset.store_layout import ArraySpec, layout

#: root attribute holding {"arrays": {name: sha256}, "attributes": sha256, "data": [names]}
STATIC_ATTR = "static_checksums"
#: root attributes that are functions of the spec's content and that readers interpret
CHECKED_ATTRS = ("raysim_dataset_format", "description", "samples", "seed", "method", "radiator",
                 "radiator_tol", "sampling", "focal_length", "diameter", "sphere_radius", "theta_min",
                 "theta_max", "phi_min", "phi_max", "validation_fraction", "models", "measurement",
                 "status_meanings")
#: text attributes compared by their TOML content (comments and layout may differ)
TEXT_ATTRS = ("spec", "scene")
#: per-sample arrays that record a run rather than a sample's data (not in its checksum)
BOOKKEEPING = frozenset({"status", "error", "checksum", "seconds", "cpu_seconds", "finished"})
_DONE = 1


class CorruptStoreError(DatasetError):
    """A store's creation-time arrays or attributes do not match what it recorded."""


class CorruptSampleError(DatasetError):
    """A sample (or an ideal intensity) read back does not match its checksum."""


def resume_hint(path: str) -> str:
    """The command that recomputes (or rewrites) what failed a check in the store ``path``."""
    return f"run `raysim dataset SPEC -o {path} --resume` with the store's spec to recompute it"


def checksum(values: dict[str, np.ndarray], identity: str = "") -> str:
    """SHA-256 (hex) of ``identity`` (which unit the values are), then of named arrays: each
    name, then its values' bytes in C order."""
    sha = hashlib.sha256(identity.encode())
    for name in sorted(values):
        sha.update(name.encode())
        sha.update(np.ascontiguousarray(values[name]).tobytes())
    return sha.hexdigest()


def binding(attrs: Any) -> str:
    """What a store's checksums hash before the unit's own identity: since format 3 the spec's
    fingerprint (``attrs``: the store's root attributes), so a sample copied in from a store
    of another spec with the same seed fails; "" in format 2."""
    made = attrs.get("raysim_dataset_format")
    return f"store {attrs.get('fingerprint', '')}\n" if isinstance(made, int) and made >= 3 else ""


def sample_checksum(values: dict[str, np.ndarray], index: int, seed: int, bound: str = "") -> str:
    """The checksum of sample ``index`` (whose seed is ``seed``) holding ``values``: its index
    and seed are hashed with its data, so a sample's chunks moved to another sample's place
    (a bad merge or copy of stores) fail it, as a single damaged chunk does; ``bound``: the
    store's :func:`binding`."""
    return checksum(values, f"{bound}sample {int(index)} seed {int(seed)}\n")


def ideal_checksum(values: np.ndarray, f_index: int, bound: str = "") -> str:
    """The checksum of the ideal intensity of frequency ``f_index`` (its index and the store's
    :func:`binding` hashed too)."""
    return checksum({"intensity_ideal": values}, f"{bound}frequency {int(f_index)}\n")


def is_data(array: ArraySpec | Any, name: str) -> bool:
    """Whether an array (a layout entry or a stored array) is a per-sample data array: one
    sample per chunk, numeric, not bookkeeping. The rule every checksum was made with."""
    dims = tuple(array.dims if isinstance(array, ArraySpec) else array.metadata.dimension_names or ())
    return (dims[:1] == ("sample",) and array.chunks[0] == 1 and name not in BOOKKEEPING
            and np.dtype(array.dtype).kind in "biuf")


def spec_data_names(spec: DatasetSpec) -> list[str]:
    """The per-sample data arrays the spec's layout gives (what a checksum covers), sorted."""
    return sorted(name for name, array in layout(spec).items() if is_data(array, name))


def static_names(spec: DatasetSpec) -> list[str]:
    """The arrays written once at creation: the coordinates, ``seed`` and ``split``."""
    return sorted([*(name for name, a in layout(spec).items() if a.values is not None), "seed", "split"])


def static_arrays(spec: DatasetSpec) -> dict[str, np.ndarray]:
    """The arrays written once at creation, as the spec gives them, in their stored dtypes."""
    from raysim.dataset.sampling import sample_seed, validation_mask

    specs = layout(spec)
    out = {name: np.asarray(a.values, dtype=a.dtype) for name, a in specs.items() if a.values is not None}
    out["seed"] = np.array([sample_seed(spec.seed, i) for i in range(spec.samples)], dtype=np.uint64)
    out["split"] = validation_mask(spec).astype(np.int8)
    return out


# --- a resume: refuse what cannot be trusted, rewrite what the spec gives --------------------------
@dataclass
class Repairs:
    """What a resume rewrites from the spec: arrays (name -> values), root attributes, and the
    metadata (``zarr.json``) of arrays whose metadata is missing or unreadable."""

    arrays: dict[str, np.ndarray] = field(default_factory=dict)
    attributes: dict[str, Any] = field(default_factory=dict)
    array_attributes: dict[str, dict[str, Any]] = field(default_factory=dict)  # name -> its attributes
    metadata: tuple[str, ...] = ()  # arrays whose zarr.json is rewritten from the layout

    @property
    def names(self) -> tuple[str, ...]:
        """What is rewritten, for the run's summary (attributes as ``attribute NAME``, an
        array's own as ``NAME attributes``, its lost ``zarr.json`` as ``NAME metadata``)."""
        attrs = [k for k in self.attributes if k not in ("spec_source", "spec_base")]
        return (*(f"{k} metadata" for k in self.metadata),
                *sorted(k for k in self.arrays if k not in self.metadata),
                *(f"{k} attributes" for k in sorted(self.array_attributes)),
                *(f"attribute {k}" for k in attrs))


def check_store(group: zarr.Group, path: str, spec: DatasetSpec,
                static: dict[str, np.ndarray] | None = None) -> Repairs:
    """Refuse (DatasetError, one line naming the store and the array, nothing touched) a store
    an array of which has metadata that do not match the spec's layout (another shape, chunks or
    type: not an array this spec made); return what to rewrite from the spec: the arrays whose
    metadata is missing or unreadable (:func:`restore_metadata`), the creation-time arrays and
    the attributes that no longer match. ``static``: :func:`static_arrays` of the spec, when
    the caller has them already."""
    made = layout_metadata(spec)
    lost = tuple(name for name, array in layout(spec).items()
                 if not _check_array(group, path, name, array, made[name]))
    static = static_arrays(spec) if static is None else static
    arrays = {name: values for name, values in static.items()
              if name in lost or not _holds(group[name], values)}
    return Repairs(arrays, _attribute_repairs(dict(group.attrs), spec),
                   _array_attribute_repairs(group, spec, lost), lost)


def layout_metadata(spec: DatasetSpec) -> dict[str, Any]:
    """Each array's metadata (``zarr.json``) as the spec's layout makes it: the same call the
    store's creation made (store._fill), in a scratch store, so the same document."""
    specs = layout(spec)
    scratch = zarr.open_group(zarr.storage.MemoryStore(), mode="w")
    return {name: scratch.create_array(name, shape=a.shape, chunks=a.chunks, dtype=a.dtype,
                                       fill_value=a.fill, dimension_names=a.dims,
                                       attributes=a.attrs).metadata for name, a in specs.items()}


def restore_metadata(group: zarr.Group, spec: DatasetSpec, names: Sequence[str]) -> None:
    """Write the ``zarr.json`` of the arrays ``names`` as the spec's layout makes it (the bytes
    a new store holds), leaving their chunks: the data of each sample are then read again and
    verified against its checksum, so one lost metadata file costs nothing that is intact, and
    an array removed whole reads as its fill value, whose samples fail and are recomputed."""
    from zarr.core.buffer import default_buffer_prototype
    from zarr.core.sync import sync

    if not names:
        return
    made = layout_metadata(spec)
    for name in names:
        document = made[name].to_buffer_dict(default_buffer_prototype())["zarr.json"]
        sync((group.store_path / name / "zarr.json").set(document))


def _array_attribute_repairs(group: zarr.Group, spec: DatasetSpec,
                             lost: Sequence[str] = ()) -> dict[str, dict[str, Any]]:
    """The arrays whose own attributes are not the layout's (an ``add_offset`` or
    ``scale_factor`` added, which xarray would apply on reading): name -> the layout's. The
    ``lost`` arrays' metadata, attributes included, is rewritten whole."""
    return {name: array.attrs for name, array in layout(spec).items()
            if name not in lost and _json(dict(group[name].attrs)) != _json(array.attrs)}


def _check_array(group: zarr.Group, path: str, name: str, array: ArraySpec, made: Any) -> bool:
    """Whether the array's metadata can be read and are the layout's ``made`` (False: missing,
    unreadable, or another codec chain or fill value, for the resume to rewrite from the
    layout; its attributes are compared on their own); refuse one whose shape, chunks or type
    differ from it."""
    try:
        arr = group[name]
        meta = (tuple(arr.shape), tuple(arr.chunks), tuple(arr.metadata.dimension_names or ()), arr.dtype)
    except Exception:
        return False
    want = np.dtype(array.dtype)
    same_type = np.dtype(meta[3]).kind in "TUO" if want.kind == "U" else np.dtype(meta[3]) == want
    if meta[:3] != (array.shape, array.chunks, array.dims) or not same_type:
        raise DatasetError(f"{path}: its array {name!r} does not have the shape, chunks or type its "
                           f"spec gives ({meta[0]} {meta[3]}, expected {array.shape} {want}); the "
                           "store was left as it is: make the dataset again at a new store path")
    # a codec lost from zarr.json (the chunks still compressed) read every sample as garbage,
    # recomputed them and wrote them on uncompressed: the layout's document is put back instead
    return _document(arr.metadata) == _document(made)


def _document(metadata: Any) -> str:
    """An array's metadata as comparable text, its attributes left out."""
    return json.dumps({k: v for k, v in metadata.to_dict().items() if k != "attributes"},
                      sort_keys=True, default=str)


def _holds(arr: Any, values: np.ndarray) -> bool:
    """Whether ``arr`` reads back as ``values`` (NaN where NaN); False if it cannot be read."""
    try:
        stored = np.asarray(arr[...])
    except Exception:
        return False
    return stored.shape == values.shape and np.array_equal(stored, values,
                                                           equal_nan=values.dtype.kind == "f")


def _attribute_repairs(stored: dict[str, Any], spec: DatasetSpec) -> dict[str, Any]:
    from raysim.dataset.store import spec_attributes

    want = spec_attributes(spec)
    out = {k: want[k] for k in CHECKED_ATTRS if _json(stored.get(k)) != _json(want[k])}
    if not same_toml(stored.get("spec"), spec.text):
        out["spec"] = spec.text
    # workers resolve the files the scene names against spec_base: after the project folder
    # was moved or copied it must be the spec given to this resume, never the old folder's
    where = {"spec_source": spec.source, "spec_base": str(spec.base)}
    out.update({k: v for k, v in where.items() if stored.get(k) != v})
    if not same_toml(stored.get("scene"), spec.scene_text):
        out["scene"] = spec.scene_text
    return out


def _json(value: Any) -> str:
    return json.dumps(value, sort_keys=True)


def same_toml(stored: Any, text: str) -> bool:
    """Whether ``stored`` is TOML text with the content of ``text`` (comments aside)."""
    if not isinstance(stored, str):
        return False
    try:
        return tomllib.loads(stored) == tomllib.loads(text)
    except Exception:  # not TOML (or nested beyond the parser)
        return False


def repair(group: zarr.Group, repairs: Repairs, spec: DatasetSpec) -> None:
    """Rewrite what :func:`check_store` found from the spec, then record the store's static
    checksums (what readers compare with) as they now are."""
    for name, values in repairs.arrays.items():
        group[name][...] = values
    for name, attrs in repairs.array_attributes.items():
        group[name].attrs.put(attrs)
    if repairs.attributes:
        group.attrs.update(repairs.attributes)
    record_static(group, spec)


def record_static(group: zarr.Group, spec: DatasetSpec) -> None:
    """Write :data:`STATIC_ATTR`: the checksums of the creation-time arrays and of the checked
    root attributes as stored now, of every array's own attributes, and the names of the
    per-sample data arrays."""
    arrays = {name: checksum({name: np.asarray(group[name][...])}) for name in static_names(spec)}
    current = {"arrays": arrays, "attributes": _attributes_checksum(dict(group.attrs)),
               "array_attributes": {name: _own_attributes_checksum(group[name]) for name in layout(spec)},
               "data": spec_data_names(spec)}
    if group.attrs.get(STATIC_ATTR) != current:
        group.attrs[STATIC_ATTR] = current


def _own_attributes_checksum(arr: Any) -> str:
    """SHA-256 of an array's own attributes: the CF ones (``add_offset``, ``scale_factor``,
    ``_FillValue``, ``units``) change what xarray returns for the same stored values."""
    return hashlib.sha256(_json(dict(arr.attrs)).encode()).hexdigest()


def _attributes_checksum(attrs: dict[str, Any]) -> str:
    chosen = {k: attrs.get(k) for k in (*CHECKED_ATTRS, *TEXT_ATTRS)}
    return hashlib.sha256(_json(chosen).encode()).hexdigest()


# --- readers: no spec, the checksums recorded in the store ------------------------------------------
def check_static(group: zarr.Group, path: str) -> None:
    """Refuse (CorruptStoreError) a store whose creation-time arrays, their attributes, the
    arrays' own attributes or the checked root attributes no longer match the checksums it
    recorded, or that records none (every store of this format records them when made: their
    absence is damage, which would switch every check here off)."""
    sums = group.attrs.get(STATIC_ATTR)
    if not isinstance(sums, dict) or not all(isinstance(sums.get(k), dict)
                                             for k in ("arrays", "array_attributes")):
        raise CorruptStoreError(f"{path}: its attribute {STATIC_ATTR!r} (what its coordinates, split "
                                f"and attributes are checked against) is missing or damaged; "
                                f"{resume_hint(path)}")
    if _attributes_checksum(dict(group.attrs)) != sums.get("attributes"):
        raise CorruptStoreError(f"{path}: its attributes (diameter, sphere, spec, ...) were changed "
                                f"since it was made; run `raysim dataset SPEC -o {path} --resume` "
                                "with the store's spec to rewrite them")
    _check_array_attributes(group, path, sums["array_attributes"])
    _check_codecs(group, path)
    for name, expected in sums["arrays"].items():
        try:
            actual = checksum({name: np.asarray(group[name][...])})
        except Exception:
            actual = None
        if actual != expected:
            raise CorruptStoreError(f"{path}: its array {name!r} was removed or damaged since it was "
                                    f"made; run `raysim dataset SPEC -o {path} --resume` with the "
                                    "store's spec to rewrite it")


def _check_array_attributes(group: zarr.Group, path: str, expected: dict[str, Any]) -> None:
    """Refuse a store an array of which has other own attributes (``add_offset``, ``units``,
    ...) than when it was made, or whose metadata cannot be read, naming the array."""
    for name, digest in expected.items():
        try:
            actual = _own_attributes_checksum(group[name])
        except Exception:
            actual = None
        if actual != digest:
            raise CorruptStoreError(f"{path}: its array {name!r} is missing, its metadata cannot be read "
                                    f"or its attributes (units, add_offset, ...) were changed since "
                                    f"it was made; {resume_hint(path)}")


def _check_codecs(group: zarr.Group, path: str) -> None:
    """Refuse a store an array of which is not stored as raysim writes it: the codec chain
    (compression) and the rest of its ``zarr.json`` that Zarr derives from its shape, chunks,
    type and fill value. A codec dropped from the file read every chunk as the wrong bytes (a
    NumPy error from xarray, garbage elsewhere). Only for a store this Zarr version wrote: the
    defaults it derives may differ in another (its data are still verified by their checksums
    where they are read)."""
    from importlib import metadata

    if group.attrs.get("version_zarr") != metadata.version("zarr"):
        return
    scratch = zarr.open_group(zarr.storage.MemoryStore(), mode="w")
    try:
        arrays = list(group.arrays())
    except Exception as exc:
        raise CorruptStoreError(f"{path}: the metadata of one of its arrays cannot be read "
                                f"({type(exc).__name__}); {resume_hint(path)}") from exc
    for name, arr in arrays:
        m = arr.metadata
        made = scratch.create_array(name, shape=arr.shape, chunks=arr.chunks, dtype=m.data_type,
                                    fill_value=m.fill_value, dimension_names=m.dimension_names)
        if _document(m) != _document(made.metadata):
            raise CorruptStoreError(f"{path}: its array {name!r} is not stored as raysim writes it "
                                    f"(its zarr.json's codecs were changed); {resume_hint(path)}")
        if not _layout_fill(arr.dtype, m.fill_value):  # what a lost chunk reads as
            raise CorruptStoreError(f"{path}: its array {name!r} is not stored as raysim writes it "
                                    f"(its zarr.json's fill value was changed to {m.fill_value!r}); "
                                    f"{resume_hint(path)}")


def _layout_fill(dtype: np.dtype, fill: Any) -> bool:
    """Whether ``fill`` is the fill value the layout gives an array of ``dtype``
    (raysim.dataset.store_layout: NaN for floating point, 0 for integers): a lost chunk of a
    float array must read as NaN, never as numbers (a fill of 0.0 made a missing sample's
    intensity zeros)."""
    if dtype.kind == "f":
        return bool(np.isnan(fill))
    if dtype.kind in "iu":
        return fill == 0
    return True


def listed_data_names(group: zarr.Group, path: str = "the store") -> list[str]:
    """The per-sample data arrays present in a store (:func:`is_data`), sorted; a listing that
    fails (an array's ``zarr.json`` garbled) raises CorruptStoreError."""
    try:
        return sorted(name for name, arr in group.arrays() if is_data(arr, name))
    except Exception as exc:
        raise CorruptStoreError(f"{path}: the metadata of one of its arrays cannot be read "
                                f"({type(exc).__name__}); {resume_hint(path)}") from exc


def data_names(group: zarr.Group, path: str = "the store") -> list[str]:
    """The per-sample data arrays of a store: as recorded at creation, else as listed."""
    sums = group.attrs.get(STATIC_ATTR)
    if isinstance(sums, dict) and isinstance(sums.get("data"), list):
        return [str(n) for n in sums["data"]]
    return listed_data_names(group, path)


def open_arrays(group: zarr.Group, path: str, names: Sequence[str]) -> dict[str, Any]:
    """The arrays ``names`` of a store and its ``status``, ``checksum`` and ``seed``, opened once
    (CorruptStoreError, naming the array, where one is missing or its metadata unreadable)."""
    out = {}
    for name in (*names, "status", "checksum", "seed"):
        try:
            out[name] = group[name]
        except Exception as exc:
            raise CorruptStoreError(f"{path}: its array {name!r} is missing or its metadata cannot be "
                                    f"read ({type(exc).__name__}); run `raysim dataset SPEC -o {path} "
                                    "--resume` to see what can be repaired") from exc
    return out


#: the per-item records besides the data (one small chunk an item), which no checksum covers:
#: :func:`raysim.dataset.reading.open_dataset` reads them through :class:`GuardedRecords`
RECORDS = (*sorted(BOOKKEEPING), "ideal_status", "ideal_checksum", "ideal_error")


class GuardedRecords:
    """A store's record array read through as it is stored, a chunk that does not decode raised
    as CorruptStoreError naming the store, the array and the item (not zstd's RuntimeError), for
    ``dask.array.from_array``: the records stay lazy, as the data arrays do (reading all of them
    to check them would cost a file read per item and array when the store is opened)."""

    def __init__(self, arr: Any, path: str, name: str) -> None:
        self.arr, self.path, self.name = arr, path, name
        self.shape, self.dtype, self.ndim = tuple(arr.shape), arr.dtype, len(arr.shape)

    def __getitem__(self, key: Any) -> np.ndarray:
        try:
            return np.asarray(self.arr[key])
        except Exception as exc:
            first = key[0] if isinstance(key, tuple) and key else key
            where = f" at {(self.arr.metadata.dimension_names or ('item',))[0]} {first.start or 0}" \
                if isinstance(first, slice) else ""
            raise CorruptStoreError(f"{self.path}: its array {self.name!r} cannot be read{where} (a "
                                    f"chunk was damaged: {type(exc).__name__}); run `raysim dataset SPEC "
                                    f"-o {self.path} --resume` with the store's spec to rewrite it") from exc


def read_verified(arrays: dict[str, Any], path: str, indices: Sequence[int] | np.ndarray,
                  names: list[str], bound: str = "") -> dict[str, np.ndarray]:
    """Every data array ``names`` of the samples ``indices`` (increasing; ``arrays`` from
    :func:`open_arrays`), each sample checked done and against its checksum: name -> values
    (len(indices), ...) in the stored dtype. All the arrays are read at once (Zarr's event
    loop), and the values hashed are the values returned. A sample that fails raises
    CorruptSampleError naming the store and the sample. ``bound``: the store's :func:`binding`."""
    idx = np.asarray(indices, dtype=np.int64)
    if not len(idx):
        return {name: np.empty((0, *arrays[name].shape[1:]), dtype=arrays[name].dtype) for name in names}
    read = _read_all(arrays, idx)
    for k, index in enumerate(idx.tolist()):
        status = read["status"][k]
        if status is None or int(status) != _DONE:
            raise CorruptSampleError(f"{path}: sample {index} is not done; {resume_hint(path)}")
        sample = {name: read[name][k] for name in names}
        stored, seed = read["checksum"][k], read["seed"][k]
        if stored is None or seed is None or any(v is None for v in sample.values()) \
                or str(stored) != sample_checksum(sample, index, int(seed), bound):
            raise CorruptSampleError(f"{path}: sample {index}'s stored data do not match its checksum "
                                     f"(a chunk was removed or damaged); {resume_hint(path)}")
    return {name: np.stack(read[name]) for name in names}


def _read_all(arrays: dict[str, Any], idx: np.ndarray) -> dict[str, list[Any]]:
    """``arrays[name][i]`` for each name and index (None where a chunk does not decode)."""
    blocks: list[Any]
    if all(hasattr(a, "_async_array") for a in arrays.values()):
        import asyncio

        from zarr.core.sync import sync

        async def read() -> list[Any]:
            return await asyncio.gather(*(a._async_array.get_orthogonal_selection((idx,))
                                          for a in arrays.values()), return_exceptions=True)

        blocks = sync(read())
    else:  # pragma: no cover - a Zarr without the async layer
        blocks = [_try(lambda a=a: a.oindex[idx]) for a in arrays.values()]
    out = {}
    for (name, arr), block in zip(arrays.items(), blocks, strict=True):
        if isinstance(block, BaseException):  # a chunk that does not decode: one by one
            out[name] = [_try(lambda i=i, arr=arr: arr[i]) for i in idx.tolist()]
        else:
            block = np.asarray(block)
            out[name] = [np.asarray(block[k]) for k in range(len(idx))]
    return out


def _try(read: Any) -> Any:
    try:
        return np.asarray(read())
    except Exception:
        return None


def read_ideals(group: zarr.Group, path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(frequencies (Hz), ideal intensities, which of them are done and match their checksum)."""
    try:
        frequencies = np.asarray(group["frequency"][...])
        arrays = {name: group[name] for name in ("ideal_status", "ideal_checksum", "intensity_ideal")}
    except Exception as exc:
        raise CorruptStoreError(f"{path}: its frequencies or ideal intensities cannot be read "
                                f"({type(exc).__name__}); {resume_hint(path)}") from exc
    read = _read_all(arrays, np.arange(arrays["intensity_ideal"].shape[0]))
    bound = binding(group.attrs)
    ok = np.array([s is not None and int(s) == _DONE and v is not None and c is not None
                   and str(c) == ideal_checksum(v, f, bound)
                   for f, (s, c, v) in enumerate(zip(read["ideal_status"], read["ideal_checksum"],
                                                     read["intensity_ideal"], strict=True))], dtype=bool)
    shape = tuple(arrays["intensity_ideal"].shape[1:])
    ideals = [v if v is not None else np.full(shape, np.nan) for v in read["intensity_ideal"]]
    return frequencies, np.stack(ideals) if ideals else np.empty((0, *shape)), ok


def ideal_of(path: str, frequencies: np.ndarray, ideals: np.ndarray, ok: np.ndarray,
             frequency: float) -> np.ndarray:
    """The verified ideal intensity of ``frequency``; a frequency the store does not list, or
    whose ideal failed its check, raises (one line naming the store)."""
    hit = np.flatnonzero(frequencies == frequency)
    if not hit.size:
        raise CorruptStoreError(f"{path}: a sample's frequency {frequency:g} Hz is not one of the "
                                f"store's (its 'frequency' array was damaged?); {resume_hint(path)}")
    f = int(hit[0])
    if not ok[f]:
        raise CorruptSampleError(f"{path}: the ideal intensity of {frequency:g} Hz is not done or does "
                                 f"not match its checksum; {resume_hint(path)}")
    return ideals[f]
