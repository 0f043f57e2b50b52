"""Atomic NetCDF writing shared by every data contract (FieldMap, SurfaceMap, scans).

A reader never sees a half-written file: the dataset goes to a temporary file in the
target folder, is flushed to disk, then renamed over the target in one step. The file gets
the mode any new file gets under the umask (0644 under 022), not the temporary file's 0600.
An operating-system failure names the target, never the temporary file.
"""

from __future__ import annotations

import errno
import os
import shutil
from pathlib import Path

import numpy as np
import xarray as xr

from raysim.files import atomic_path


def canonical_order(ds: xr.Dataset, dims: tuple[str, str], unit: str, source: str,
                    error: type[Exception]) -> xr.Dataset:
    """``ds`` with both coordinates of ``dims`` ascending and its 2-D variables in ``dims``
    order: a legal file may store a coordinate descending, or the variables transposed, and
    every reader must see the same arrays. A coordinate that is missing, not 1-D, not finite
    or not strictly monotonic raises ``error`` (one line naming ``source``)."""
    for coord in dims:
        if coord not in ds.coords:
            raise error(f"{source}: missing coordinate '{coord}'")
        values = np.asarray(ds[coord].values)
        if values.ndim != 1 or ds[coord].dims != (coord,):
            raise error(f"{source}: coordinate '{coord}' must be 1-D along its own dimension")
        if not np.issubdtype(values.dtype, np.number) or not np.all(np.isfinite(values)):
            raise error(f"{source}: coordinate '{coord}' must hold finite numbers ({unit})")
        steps = np.diff(values)
        if values.size > 1 and not (np.all(steps > 0) or np.all(steps < 0)):
            raise error(f"{source}: coordinate '{coord}' must be strictly monotonic "
                        "(each value once, in order)")
        if values.size > 1 and steps[0] < 0:
            ds = ds.isel({coord: slice(None, None, -1)})
    if any(ds[name].dims == dims[::-1] for name in ds.data_vars):
        ds = ds.transpose(*dims, ...)
    return ds


def check_file(path: str | os.PathLike[str], error: type[Exception]) -> Path:
    """``path`` if it names a regular file; else raise ``error`` with one line (a folder, or
    nothing there): a command checks its input so before it makes any output folder."""
    path = Path(path)
    if path.is_dir():
        raise error(f"{path}: is a folder, give a NetCDF file")
    if not path.is_file():
        raise error(f"{path}: no such file")
    return path


def read(path: str | os.PathLike[str], error: type[Exception]) -> xr.Dataset:
    """Load a NetCDF file whole into memory; raise ``error`` with one line if it cannot be read."""
    path = check_file(path, error)
    try:
        with xr.open_dataset(path) as ds:
            return ds.load()
    except Exception as exc:  # every backend failure means "not a NetCDF file we can read"
        raise error(f"{path}: not a readable NetCDF file ({exc.__class__.__name__})") from None


def write_atomic(ds: xr.Dataset, path: str | os.PathLike[str],
                 error: type[Exception] = ValueError) -> Path:
    """Write ``ds`` to ``path`` as NetCDF-4 so that ``path`` is either old or complete
    (:func:`raysim.files.atomic_path`); an attribute NetCDF cannot store raises ``error``
    first (:func:`check_attrs`)."""
    check_attrs(ds, error)
    with atomic_path(path) as tmp:
        try:
            ds.to_netcdf(tmp, engine="netcdf4", format="NETCDF4")
        except (RuntimeError, PermissionError) as exc:
            # the NetCDF library reports a full disk as "NetCDF: HDF error" (RuntimeError), or
            # as a permission error when not even its header fits: say what it most likely is
            if _nearly_full(tmp):
                raise OSError(errno.ENOSPC, "no space left on the device") from None
            raise OSError(errno.EIO, f"the NetCDF library could not write it ({exc})") from None
    return Path(path)


def _nearly_full(path: Path) -> bool:
    """Whether the file system holding ``path`` has less than 1 MiB free."""
    try:
        return shutil.disk_usage(path.parent).free < 2**20
    except OSError:
        return False


def check_attrs(ds: xr.Dataset, error: type[Exception]) -> None:
    """Refuse (``error``, one line) an attribute of ``ds`` or of its variables that NetCDF
    cannot store: anything but text, a real number or a 1-D array of real numbers (None,
    a bool, a dict or a complex number failed inside netCDF4 with a TypeError)."""
    for owner, attrs in [("", ds.attrs), *((f"{name}: ", ds[name].attrs) for name in ds.variables)]:
        for key, value in attrs.items():
            if isinstance(value, str | bytes):
                continue
            values = np.asarray(value) if isinstance(value, list | tuple | np.ndarray | np.generic
                                                     | int | float) else None
            if (values is None or values.ndim > 1 or values.dtype == np.bool_
                    or not np.issubdtype(values.dtype, np.number)
                    or np.issubdtype(values.dtype, np.complexfloating)):
                raise error(f"attribute {owner}{key!r} = {value!r} cannot be stored in NetCDF: "
                            "give text, a real number or a list of real numbers (0 or 1 for "
                            "yes or no)")


def check_real(arr: np.ndarray, name: str, source: str, error: type[Exception],
               quantity: str) -> None:
    """Refuse (``error``, one line) a variable ``name`` whose values are not real numbers:
    complex (numpy counts complex as a number, and a float conversion would drop the imaginary
    part), text or booleans. ``quantity`` says what it holds (``an intensity``)."""
    if np.iscomplexobj(arr):
        raise error(f"{source}: variable '{name}' holds complex values: {quantity} must be real")
    if arr.dtype == np.bool_ or not np.issubdtype(arr.dtype, np.number):
        raise error(f"{source}: variable '{name}' must hold numbers, got dtype {arr.dtype}")
