"""SurfaceMap: the recovered main-reflector deformation as an ``xarray.Dataset`` (NetCDF on disk).

The contract the solver writes and the renderer, the hardware crew and the tests read
(``docs/data.md``); :mod:`solver.surface` re-exports it under its old name:

- coordinates ``x``, ``y``: aperture-plane cell centres (m), N each, over [-D/2, D/2];
- ``deformation`` (y, x): delta along z (m), real, NaN outside the aperture r < D/2;
- optional ``truth`` (y, x) and ``error`` = deformation - truth (m) when the truth is known,
  ``deformation_std`` (y, x) (m) when the scan carried ``intensity_std`` (or, without it,
  when the noise estimated from the scan spreads the map by a tenth of its RMS or more), with
  ``deformation_noise_draws`` (draw, y, x) (m, float32): the Monte Carlo's draws of the map's
  noise whose spread ``deformation_std`` is, each less their mean (what :mod:`solver.correction`
  propagates to the commands: the noise is correlated across the dish);
- attributes: ``solver``, ``boundary`` (what the rim values were), ``harmonic_part``
  (``unobservable`` without rim targets, else ``fixed by rim targets``), ``removed_terms`` and
  a ``removed_<coefficient>`` per removed coefficient, ``rms_m`` and ``rrms`` when the truth is
  known, ``focal_length``, ``diameter``, ``sphere_radius`` (m) and the inversion's settings.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from raysim.errors import SurfaceMapError
from raysim.maps.aperture import ApertureGrid, cell_centres
from raysim.maps.netcdf import canonical_order, check_real, read, write_atomic
from raysim.version import VERSION_ATTR, __version__

REQUIRED_ATTRS = ("solver", "boundary", "harmonic_part", "removed_terms", "focal_length",
                  "diameter", "sphere_radius")
OPTIONAL_VARS = ("truth", "error", "deformation_std")
#: the Monte Carlo draws of the map's noise (draw, y, x), m, less their mean
NOISE_DRAWS = "deformation_noise_draws"
#: the two values of the ``harmonic_part`` attribute: without rim targets, and with them
HARMONIC_UNOBSERVABLE = "unobservable"
HARMONIC_FIXED = "fixed by rim targets"
LONG_NAMES = {
    "deformation": "recovered surface deformation along z",
    "truth": "true surface deformation along z (same terms removed)",
    "error": "deformation - truth",
    "deformation_std": "standard deviation of deformation from the intensity noise",
    NOISE_DRAWS: "Monte Carlo draws of the deformation's noise, less their mean",
}


def surfacemap(grid: ApertureGrid, deformation: np.ndarray, attrs: Mapping[str, Any], *,
               truth: np.ndarray | None = None, deformation_std: np.ndarray | None = None,
               noise_draws: np.ndarray | None = None) -> xr.Dataset:
    """Assemble a SurfaceMap on the aperture ``grid`` (deformation, truth, std in m, (N, N);
    ``noise_draws`` (draws, N, N), m, the Monte Carlo's draws of the noise less their mean).

    ``attrs`` must hold at least :data:`REQUIRED_ATTRS`; values are flat numbers or strings.
    ``error`` is added when ``truth`` is given.
    """
    dims = ("y", "x")
    fields = {"deformation": deformation, "truth": truth, "deformation_std": deformation_std}
    if truth is not None:
        for name, values in (("deformation", deformation), ("truth", truth)):
            check_real(np.asarray(values), name, "SurfaceMap", SurfaceMapError, "a deformation")
        fields["error"] = np.asarray(deformation) - np.asarray(truth)
    data_vars = {}
    for name, values in fields.items():
        if values is None:
            continue
        arr = np.asarray(values)
        check_real(arr, name, "SurfaceMap", SurfaceMapError, "a deformation")
        arr = arr.astype(np.float64)
        if arr.shape != (grid.N, grid.N):
            raise SurfaceMapError(f"{name} has shape {arr.shape}, the grid is {(grid.N, grid.N)}")
        data_vars[name] = (dims, grid.masked(arr), {"units": "m", "long_name": LONG_NAMES[name]})
    if noise_draws is not None:
        draws = np.asarray(noise_draws)
        check_real(draws, NOISE_DRAWS, "SurfaceMap", SurfaceMapError, "a deformation")
        if draws.ndim != 3 or draws.shape[1:] != (grid.N, grid.N):
            raise SurfaceMapError(f"{NOISE_DRAWS} has shape {draws.shape}, expected (draws, "
                                  f"{grid.N}, {grid.N})")
        masked = np.stack([grid.masked(d) for d in draws.astype(np.float64)]).astype(np.float32)
        data_vars[NOISE_DRAWS] = (("draw", *dims), masked,
                                  {"units": "m", "long_name": LONG_NAMES[NOISE_DRAWS]})
    coords = {
        "x": ("x", grid.x, {"units": "m", "long_name": "aperture-plane x (vertex frame)"}),
        "y": ("y", grid.y, {"units": "m", "long_name": "aperture-plane y (vertex frame)"}),
    }
    all_attrs = {VERSION_ATTR: __version__,
                 "created": datetime.now(UTC).isoformat(timespec="seconds"),
                 "Conventions": "CF-1.8", "grid_n": int(grid.N), "grid_step_m": float(grid.h)}
    all_attrs.update({k: _flat(v) for k, v in attrs.items()})
    ds = xr.Dataset(data_vars, coords=coords, attrs=all_attrs)
    if NOISE_DRAWS in ds:  # float32 noise: compressed a little (about 8 MB at N = 256, 32 draws)
        ds[NOISE_DRAWS].encoding.update(zlib=True, complevel=1)
    return validate(ds, "SurfaceMap")


def _flat(value: Any) -> Any:
    if isinstance(value, bool | np.bool_):
        return int(value)
    if isinstance(value, np.generic):
        return value.item()
    if value is None:
        return ""
    return value


def canonical(ds: xr.Dataset, source: str = "SurfaceMap") -> xr.Dataset:
    """``ds`` in canonical order: x, y ascending and dims (y, x) (a legal file may store either
    coordinate descending, or the variables transposed; the noise draws as (draw, y, x))."""
    ds = canonical_order(ds, ("y", "x"), "m", source, SurfaceMapError)
    if NOISE_DRAWS in ds.data_vars and ds[NOISE_DRAWS].dims != ("draw", "y", "x"):
        if set(ds[NOISE_DRAWS].dims) != {"draw", "y", "x"}:
            raise SurfaceMapError(f"{source}: variable '{NOISE_DRAWS}' must have dims (draw, y, x)")
        ds[NOISE_DRAWS] = ds[NOISE_DRAWS].transpose("draw", "y", "x")
    return ds


def validate(ds: xr.Dataset, source: str = "SurfaceMap") -> xr.Dataset:
    """Check ``ds`` against the contract and return it in canonical order (:func:`canonical`);
    raise :class:`SurfaceMapError` naming the first defect."""
    ds = canonical(ds, source)
    for coord in ("x", "y"):
        if ds[coord].attrs.get("units") != "m":
            raise SurfaceMapError(f"{source}: coordinate '{coord}' must be in m")
    if "deformation" not in ds.data_vars:
        raise SurfaceMapError(f"{source}: missing variable 'deformation'")
    for name in ("deformation", *OPTIONAL_VARS):
        if name not in ds.data_vars:
            continue
        if ds[name].dims != ("y", "x"):
            raise SurfaceMapError(f"{source}: variable '{name}' must have dims (y, x)")
        if ds[name].attrs.get("units") != "m":
            raise SurfaceMapError(f"{source}: variable '{name}' must be in m, "
                                  f"got {ds[name].attrs.get('units')!r}")
        check_real(np.asarray(ds[name].values), name, source, SurfaceMapError, "a deformation")
    for name in REQUIRED_ATTRS:
        if name not in ds.attrs:
            raise SurfaceMapError(f"{source}: missing attribute '{name}'")
    _check_grid(ds, source)
    for name in ("deformation", *OPTIONAL_VARS):
        if name in ds.data_vars and np.isinf(ds[name].values).any():
            raise SurfaceMapError(f"{source}: variable '{name}' holds infinite values (NaN marks "
                                  "points without data)")
    if "deformation_std" in ds.data_vars and (ds["deformation_std"].values < 0).any():
        raise SurfaceMapError(f"{source}: variable 'deformation_std' holds negative values")
    if NOISE_DRAWS in ds.data_vars:
        draws = ds[NOISE_DRAWS]
        if draws.attrs.get("units") != "m":
            raise SurfaceMapError(f"{source}: variable '{NOISE_DRAWS}' must be in m, "
                                  f"got {draws.attrs.get('units')!r}")
        check_real(np.asarray(draws.values), NOISE_DRAWS, source, SurfaceMapError, "a deformation")
        if np.isinf(draws.values).any() or draws.sizes["draw"] < 2:
            raise SurfaceMapError(f"{source}: variable '{NOISE_DRAWS}' must hold at least 2 "
                                  "finite draws (NaN marks points without data)")
    return ds


def _check_grid(ds: xr.Dataset, source: str) -> None:
    """The coordinates must be the aperture grid of the ``diameter`` attribute: N cell centres
    across it on both axes (every reader places the values by that grid)."""
    try:
        D = float(ds.attrs["diameter"])
    except (TypeError, ValueError):
        raise SurfaceMapError(f"{source}: attribute 'diameter' must be a number (m)") from None
    if not (np.isfinite(D) and D > 0):
        raise SurfaceMapError(f"{source}: attribute 'diameter' must be > 0 m, got {D:g}")
    nx, ny = int(ds.sizes["x"]), int(ds.sizes["y"])
    if nx != ny or nx < 2:
        raise SurfaceMapError(f"{source}: the grid must be square, N x N with N >= 2 (x {nx}, y {ny})")
    expected = cell_centres(D, nx)
    for coord in ("x", "y"):
        if not np.allclose(ds[coord].values, expected, rtol=0.0, atol=1e-6 * D):
            raise SurfaceMapError(f"{source}: coordinate '{coord}' is not the {nx} cell centres "
                                  f"across the diameter {D:g} m (-D/2 + (i + 1/2) D / N)")


def grid_of(ds: xr.Dataset) -> ApertureGrid:
    """The aperture grid of a SurfaceMap, from its diameter attribute and x coordinate."""
    return ApertureGrid(float(ds.attrs["diameter"]), int(ds.sizes["x"]))


def save(ds: xr.Dataset, path: str | os.PathLike[str]) -> Path:
    """Write a SurfaceMap atomically (temporary file + rename) as NetCDF-4."""
    return write_atomic(validate(ds), path, SurfaceMapError)


def load(path: str | os.PathLike[str]) -> xr.Dataset:
    """Read and check a SurfaceMap; raise :class:`SurfaceMapError` with one line if unusable."""
    return validate(read(path, SurfaceMapError), source=str(path))
