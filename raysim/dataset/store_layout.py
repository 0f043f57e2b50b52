"""The arrays of a dataset store (see :mod:`raysim.dataset.store`): names, dims, units, chunks.

Arrays that workers write have one sample per chunk; the coordinates and the arrays the
client writes once at creation (``seed``, ``split``) have large chunks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from raysim.dataset.effects import PREFIX, VARIABLES
from raysim.dataset.spec import DatasetSpec

#: the store's format (attribute ``raysim_dataset_format``); 2: a sample's checksum hashes its
#: index and seed with its data, an ideal intensity's its frequency's index (1 did not); 3: both
#: hash the spec's fingerprint too, so a sample copied from a store of another spec fails
FORMAT = 3
#: the formats this raysim reads and resumes (each checked as its own format hashes)
READ_FORMATS = (2, 3)
_COORD_CHUNK = 65536


@dataclass(frozen=True)
class ArraySpec:
    """One array: dims, shape, chunks, dtype, fill value, attributes, values written at creation."""

    dims: tuple[str, ...]
    shape: tuple[int, ...]
    chunks: tuple[int, ...]
    dtype: str
    fill: Any
    attrs: dict[str, Any] = field(default_factory=dict)
    values: np.ndarray | None = None


def _coord(values: np.ndarray, dim: str, units: str, long_name: str) -> ArraySpec:
    values = np.asarray(values)
    fill = np.nan if values.dtype.kind == "f" else 0
    return ArraySpec((dim,), values.shape, (max(1, min(len(values), _COORD_CHUNK)),),
                     values.dtype.name, fill, {"units": units, "long_name": long_name}, values)


def _per_sample(n: int, extra_dims: tuple[str, ...], extra: tuple[int, ...], dtype: str, fill: Any,
                units: str, long_name: str, **attrs: Any) -> ArraySpec:
    return ArraySpec(("sample", *extra_dims), (n, *extra), (1, *extra), dtype, fill,
                     {"units": units, "long_name": long_name, **attrs})


def layout(spec: DatasetSpec) -> dict[str, ArraySpec]:
    """Every array of the store of ``spec``, by name."""
    n = spec.samples
    sphere = spec.scene.sphere
    nt, nph = sphere.n_theta, sphere.n_phi
    grid = spec.grid
    nf = len(spec.frequencies)
    flags = {"flag_values": [0, 1, 2], "flag_meanings": "pending done failed"}
    out: dict[str, ArraySpec] = {
        "sample": _coord(np.arange(n, dtype=np.int64), "sample", "1", "sample index"),
        "theta": _coord(sphere.theta, "theta", "rad", "polar angle from -z at the focus"),
        "phi": _coord(sphere.phi, "phi", "rad", "azimuth atan2(y, x) at the focus"),
        "x": _coord(grid.x, "x", "m", "aperture x (cell centres)"),
        "y": _coord(grid.y, "y", "m", "aperture y (cell centres)"),
        "frequency": _coord(np.array(spec.frequencies), "frequency", "Hz", "frequency of the plane wave"),
        "intensity": _per_sample(n, ("theta", "phi"), (nt, nph), spec.dtype, np.nan, "1",
                                 "intensity |E|^2 of the deformed reflector",
                                 reference="incident plane-wave intensity"),
        "intensity_ideal": ArraySpec(("frequency", "theta", "phi"), (nf, nt, nph), (1, nt, nph),
                                     "float64", np.nan,
                                     {"units": "1", "long_name": "intensity |E|^2 of the ideal paraboloid",
                                      "reference": "incident plane-wave intensity"}),
        "ideal_status": ArraySpec(("frequency",), (nf,), (1,), "int8", 0,
                                  {"units": "1", "long_name": "status of intensity_ideal", **flags}),
        "ideal_checksum": ArraySpec(("frequency",), (nf,), (1,), "str", "",
                                    {"units": "1",
                                     "long_name": "SHA-256 of the frequency's index and intensity_ideal "
                                                  "(hex, raysim.dataset.integrity.ideal_checksum)"}),
        "ideal_error": ArraySpec(("frequency",), (nf,), (1,), "str", "",
                                 {"units": "1", "long_name": "why the ideal intensity failed"}),
        "deformation": _per_sample(n, ("y", "x"), (grid.N, grid.N), spec.dtype, np.nan, "m",
                                   "surface error delta along +z (NaN outside the aperture)"),
        "seed": ArraySpec(("sample",), (n,), (min(n, _COORD_CHUNK),), "uint64", 0,
                          {"units": "1", "long_name": "numpy SeedSequence entropy of the sample"}),
        "split": ArraySpec(("sample",), (n,), (min(n, _COORD_CHUNK),), "int8", 0,
                           {"units": "1", "long_name": "0 train, 1 validation",
                            "flag_values": [0, 1], "flag_meanings": "train validation"}),
        "frequency_hz": _per_sample(n, (), (), "float64", np.nan, "Hz", "frequency of this sample"),
        "rms": _per_sample(n, (), (), "float64", np.nan, "m", "RMS of delta over the aperture grid"),
        "peak_to_peak": _per_sample(n, (), (), "float64", np.nan, "m",
                                    "peak-to-peak of delta over the aperture grid"),
        "status": _per_sample(n, (), (), "int8", 0, "1", "sample status (completion marker)", **flags),
        "error": _per_sample(n, (), (), "str", "", "1", "why the sample failed"),
        "checksum": _per_sample(n, (), (), "str", "", "1",
                                "SHA-256 of the sample's index, seed and data arrays "
                                "(hex, raysim.dataset.integrity.sample_checksum)"),
        "seconds": _per_sample(n, (), (), "float64", np.nan, "s", "wall-clock time of the sample's task"),
        "cpu_seconds": _per_sample(n, (), (), "float64", np.nan, "s",
                                   "CPU time of the sample's task (all threads of its worker process)"),
        "finished": _per_sample(n, (), (), "float64", np.nan, "s",
                                "when the sample was finished (UNIX time)"),
    }
    if spec.measurement is not None:
        out["intensity_measured"] = _per_sample(
            n, ("theta", "phi"), (nt, nph), spec.dtype, np.nan, "1",
            "intensity as measured: the clean intensity with the sample's measurement effects "
            "(NaN: a missing point)", reference="incident plane-wave intensity")
        for key, (units, meaning) in VARIABLES.items():
            dtype = "int64" if key == "readings" else "float64"
            out[f"{PREFIX}{key}"] = _per_sample(n, (), (), dtype, 0 if dtype == "int64" else np.nan,
                                                units, f"measurement: {meaning}")
    for model in spec.models:
        p = model.name
        out[f"{p}_present"] = _per_sample(n, (), (), "int8", 0, "1", f"{p}: 1 if the sample has it")
        out[f"{p}_rms"] = _per_sample(n, (), (), "float64", np.nan, "m", f"{p}: RMS drawn (0: absent)")
        for key, var in model.variables(grid).items():
            out[f"{p}_{key}"] = _per_sample(n, var.dims, var.shape, "float64", np.nan, var.units,
                                            f"{p}: {var.long_name}")
            for dim, size in zip(var.dims, var.shape, strict=True):
                out.update(_model_coords(model, dim, size, grid))
    return out


def _model_coords(model: Any, dim: str, size: int, grid: Any) -> dict[str, ArraySpec]:
    if dim == "panel":
        return {"panel": _coord(np.arange(size, dtype=np.int64), "panel", "1", "panel id")}
    if dim.endswith("_term"):
        terms = np.array(model.terms, dtype=np.int64)
        return {f"{dim}_n": _coord(terms[:, 0], dim, "1", "Zernike radial order n"),
                f"{dim}_m": _coord(terms[:, 1], dim, "1", "Zernike azimuthal order m (< 0: sin)")}
    return {dim: _coord(np.arange(size, dtype=np.int64), dim, "1", f"{dim} index")}


#: a file system's allocation block (bytes): Zarr writes each chunk as a file of its own
BLOCK_BYTES = 4096


def store_bytes(spec: DatasetSpec) -> int:
    """An upper estimate (bytes) of the store of ``spec`` on disk: every chunk of every array
    uncompressed, each rounded up to a whole block (a sample's scalars are a chunk file each,
    so on small grids the files' blocks, not the data, make most of a store). The demo spec
    (scenes/dataset_demo.toml): 1.44 MB estimated, 1.12 MB on disk once written."""
    total = 0
    for array in layout(spec).values():
        dtype = np.dtype(array.dtype)
        item = dtype.itemsize if dtype.kind not in "UOT" else 64  # a text: an error line
        chunks = math.prod(-(-s // c) for s, c in zip(array.shape, array.chunks, strict=True))
        total += chunks * max(1, -(-math.prod(array.chunks) * item // BLOCK_BYTES)) * BLOCK_BYTES
    return total
