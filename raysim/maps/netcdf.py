"""Atomic NetCDF writing shared by every data contract (FieldMap, SurfaceMap, scans).

A reader never sees a half-written file: the dataset goes to a temporary file in the
target folder, is flushed to disk, then renamed over the target in one step. The file gets
the mode any new file gets under the umask (0644 under 022), not the temporary file's 0600.
An operating-system failure names the target, never the temporary file.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import xarray as xr

from raysim.files import new_file_mode


def read(path: str | os.PathLike[str], error: type[Exception]) -> xr.Dataset:
    """Load a NetCDF file whole into memory; raise ``error`` with one line if it cannot be read."""
    path = Path(path)
    if not path.is_file():
        raise error(f"{path}: no such file")
    try:
        with xr.open_dataset(path) as ds:
            return ds.load()
    except Exception as exc:  # every backend failure means "not a NetCDF file we can read"
        raise error(f"{path}: not a readable NetCDF file ({exc.__class__.__name__})") from None


def write_atomic(ds: xr.Dataset, path: str | os.PathLike[str]) -> Path:
    """Write ``ds`` to ``path`` as NetCDF-4 so that ``path`` is either old or complete."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        ds.to_netcdf(tmp, engine="netcdf4", format="NETCDF4")
        os.chmod(tmp, new_file_mode())
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
        dir_fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
