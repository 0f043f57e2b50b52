"""Deformation maps from files: the one reader (and checker) of map CSV and NetCDF files.

- NetCDF: coordinates ``x``, ``y`` (m) and a variable ``deformation`` (or ``dz``) in m; either
  coordinate may be stored descending and the variable as (x, y): both are put in canonical
  order (x, y ascending, dims (y, x)) before use.
- CSV: header ``x,y,dz`` (m), one sample per row, rows filling a regular x-y grid in any
  order; ``nan`` marks a missing sample (filled harmonically, as in the NetCDF case).

Every defect (unreadable file, text or infinite values, a coordinate that is not finite and
strictly monotonic, values too large to be metres) raises :class:`~raysim.errors.SceneError`
with one line naming the file and, for CSV, the row.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from raysim.errors import SceneError
from raysim.surface.gridded import GriddedMap

NETCDF_SUFFIXES = (".nc", ".nc4", ".netcdf")


def read_map(path: str | Path, scale: float = 1.0, *, limit_m: float = 0.1) -> GriddedMap:
    """The deformation map in ``path`` (NetCDF or CSV, metres) times ``scale``.

    ``limit_m``: the largest |dz| (after ``scale``) taken as a surface error; a larger one is
    refused as a unit mistake (a map in um or mm read as metres).
    """
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"deformation map {path}: no such file")
    if not (math.isfinite(scale) and scale > 0):
        raise SceneError(f"deformation map {path}: scale must be a finite number > 0, got {scale}")
    if path.suffix.lower() in NETCDF_SUFFIXES:
        x, y, dz = _from_netcdf(path)
    else:
        x, y, dz = _from_csv(path)
    for name, values in (("x", x), ("y", y)):
        if values.size < 4:
            raise SceneError(f"deformation map {path}: needs at least 4 {name} values, got "
                             f"{values.size}")
        if not np.all(np.isfinite(values)):
            raise SceneError(f"deformation map {path}: coordinate {name} holds a value that is not "
                             "a finite number (m)")
        if not np.all(np.diff(values) > 0):
            raise SceneError(f"deformation map {path}: coordinate {name} repeats a value")
    if np.any(np.isinf(dz)):
        raise SceneError(f"deformation map {path}: dz holds infinite values (a missing sample is "
                         "nan)")
    if not np.any(np.isfinite(dz)):
        raise SceneError(f"deformation map {path}: holds no finite dz value")
    peak = float(np.nanmax(np.abs(dz))) * scale
    if peak > limit_m:
        raise SceneError(f"deformation map {path}: |dz| reaches {peak:g} m, over {limit_m:g} m: "
                         "dz must be in metres (a map in um or mm?)")
    return GriddedMap(x, y, dz, scale)


def _from_netcdf(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    import xarray as xr

    try:
        with xr.open_dataset(path) as opened:
            ds = opened.load()
    except Exception as exc:  # every backend failure means "not a NetCDF file we can read"
        raise SceneError(f"deformation map {path}: not a readable NetCDF file "
                         f"({exc.__class__.__name__})") from None
    var = "deformation" if "deformation" in ds else "dz"
    if var not in ds.data_vars or "x" not in ds.coords or "y" not in ds.coords:
        raise SceneError(f"deformation map {path}: needs coords x, y and variable 'deformation' (m)")
    if set(ds[var].dims) != {"x", "y"}:
        raise SceneError(f"deformation map {path}: '{var}' must have dims (y, x), got {ds[var].dims}")
    units = ds[var].attrs.get("units", "m")
    if units != "m":
        raise SceneError(f"deformation map {path}: '{var}' must be in m, got {units!r}")
    for coord in ("x", "y"):
        values = np.asarray(ds[coord].values)
        if not np.issubdtype(values.dtype, np.number) or values.ndim != 1:
            raise SceneError(f"deformation map {path}: coordinate {coord} must be 1-D numbers (m)")
        finite = values[np.isfinite(values)]
        if finite.size == values.size and values.size > 1 and values[0] > values[-1]:
            ds = ds.isel({coord: slice(None, None, -1)})
    arr = ds[var].transpose("y", "x")
    return (np.asarray(ds["x"].values, dtype=np.float64), np.asarray(ds["y"].values, dtype=np.float64),
            np.asarray(arr.values, dtype=np.float64))


def read_csv_columns(path: Path, columns: Sequence[str]) -> dict[str, np.ndarray]:
    """The named numeric columns of a CSV file with a header row (``#`` lines are comments).

    Every cell must be a number (``nan`` allowed only where the caller checks for it); a
    defect names the row.
    """
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = [(n, row) for n, row in enumerate(csv.reader(fh), start=1)
                    if row and not row[0].lstrip().startswith("#")]
    except UnicodeDecodeError as exc:
        raise SceneError(f"{path}: not a text CSV file (byte {exc.start} is not UTF-8)") from exc
    except (OSError, csv.Error) as exc:
        raise SceneError(f"{path}: unreadable CSV ({exc})") from exc
    if not rows:
        raise SceneError(f"{path}: empty CSV, expected the header {','.join(columns)}")
    header = [c.strip() for c in rows[0][1]]
    missing = [c for c in columns if c not in header]
    if missing:
        raise SceneError(f"{path}: the header must name {','.join(columns)} (missing {missing[0]})")
    index = [header.index(c) for c in columns]
    values = []
    for number, row in rows[1:]:
        if len(row) != len(header):
            raise SceneError(f"{path}: row {number} has {len(row)} fields, the header {len(header)}")
        try:
            values.append([float(row[i]) for i in index])
        except ValueError:
            raise SceneError(f"{path}: row {number} is not all numbers: {','.join(row)}") from None
    if not values:
        raise SceneError(f"{path}: no data rows after the header")
    data = np.array(values, dtype=np.float64).reshape(-1, len(columns))
    out = {c: data[:, k] for k, c in enumerate(columns)}
    for c in columns:
        if np.any(np.isinf(out[c])):
            raise SceneError(f"{path}: column {c} holds an infinite value")
    return out


def _from_csv(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    data = read_csv_columns(path, ("x", "y", "dz"))
    x, y, dz = data["x"], data["y"], data["dz"]
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise SceneError(f"deformation map {path}: x and y must be finite numbers on every row")
    xs, ys = np.unique(x), np.unique(y)
    if len(xs) * len(ys) != len(x) or len(np.unique(np.column_stack([x, y]), axis=0)) != len(x):
        raise SceneError(f"deformation map {path}: rows do not fill a regular x-y grid "
                         "(each x, y pair once)")
    grid = np.full((len(ys), len(xs)), np.nan)
    grid[np.searchsorted(ys, y), np.searchsorted(xs, x)] = dz
    return xs, ys, grid
