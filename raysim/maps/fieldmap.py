"""FieldMap: intensity on the probe hemisphere as an ``xarray.Dataset`` (NetCDF on disk).

The contract (docs/data.md) every producer (GO, PO, PTD, the scanning rig) and every reader (the
solver, the renderer) shares:

- coordinates ``theta``, ``phi``: cell centres in radians (theta from -z, phi = atan2(y, x),
  both seen from the focus);
- ``intensity``: |E|^2 of the deformed (or measured) reflector relative to the incident wave,
  real and >= 0; ``intensity_ideal`` on the same grid, > 0 in one cell at least; optional
  ``intensity_std``; NaN where no sample exists;
  optional ``blocked`` (0/1): cells obstacles hide (:mod:`raysim.optics.blockage`), which
  readers treat as missing, with the obstacles' triangles ``obstacle_vertices`` (m) and
  ``obstacle_faces``;
- attributes ``focal_length``, ``diameter``, ``sphere_radius`` (m), ``frequency_hz`` (Hz),
  ``method`` (go, po, po+ptd, go+edge, measured), ``sampling`` (``cell_mean`` or ``centre``), and
  ``scene`` (the scene's TOML text) when a scene made it. A reader works from the attributes
  alone, since a measured scan has no scene.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from raysim.constants import MAX_FREQUENCY_HZ, MIN_FREQUENCY_HZ
from raysim.errors import FieldMapError
from raysim.maps.netcdf import canonical_order, check_real, read, write_atomic
from raysim.maps.sphere import SphereGrid
from raysim.methods import FIELDMAP_METHODS
from raysim.version import VERSION_ATTR, __version__

METHODS = FIELDMAP_METHODS  # re-exported: the list is defined once, in raysim.methods
SAMPLINGS = ("cell_mean", "centre")
REQUIRED_ATTRS = ("focal_length", "diameter", "sphere_radius", "frequency_hz", "method", "sampling")
REQUIRED_VARS = ("intensity", "intensity_ideal")


def fieldmap(
    grid: SphereGrid,
    intensity: np.ndarray,
    intensity_ideal: np.ndarray,
    *,
    focal_length: float,
    diameter: float,
    frequency_hz: float,
    method: str,
    sampling: str,
    intensity_std: np.ndarray | None = None,
    scene: str | None = None,
    attrs: Mapping[str, Any] | None = None,
    extra: Mapping[str, tuple[tuple[str, ...], np.ndarray, Mapping[str, Any]]] | None = None,
) -> xr.Dataset:
    """Assemble a FieldMap on ``grid``.

    Parameters
    ----------
    grid : the sphere grid (radius in m, angles in rad).
    intensity, intensity_ideal : arrays (n_theta, n_phi), |E|^2 relative to the incident wave.
    focal_length, diameter : F and D of the reflector (m).
    frequency_hz : frequency of the plane wave (Hz).
    method : one of :data:`METHODS`.
    sampling : ``cell_mean`` (power through the cell over its area) or ``centre``.
    intensity_std : optional standard deviation of ``intensity`` (same units).
    scene : the scene's TOML text, when a scene made this map.
    attrs : further flat attributes (numbers or strings) to record.
    extra : further variables, name -> (dims, values, attrs).
    """
    if method not in METHODS:
        raise FieldMapError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if sampling not in SAMPLINGS:
        raise FieldMapError(f"sampling must be one of {', '.join(SAMPLINGS)}, got {sampling!r}")
    shape = (grid.n_theta, grid.n_phi)
    dims = ("theta", "phi")
    unit = {"units": "1", "reference": "incident plane-wave intensity"}
    data_vars: dict[str, Any] = {
        "intensity": (dims, _checked(intensity, shape, "intensity"), {**unit,
                      "long_name": "intensity |E|^2 of the deformed or measured reflector"}),
        "intensity_ideal": (dims, _checked(intensity_ideal, shape, "intensity_ideal"), {**unit,
                            "long_name": "intensity |E|^2 of the ideal paraboloid"}),
    }
    if intensity_std is not None:
        data_vars["intensity_std"] = (dims, _checked(intensity_std, shape, "intensity_std"),
                                      {**unit, "long_name": "standard deviation of intensity"})
    for name, (vdims, values, vattrs) in (extra or {}).items():
        data_vars[name] = (vdims, np.asarray(values), dict(vattrs))
    all_attrs: dict[str, Any] = {
        "focal_length": float(focal_length),
        "diameter": float(diameter),
        "sphere_radius": float(grid.radius),
        "frequency_hz": float(frequency_hz),
        "method": method,
        "sampling": sampling,
        "theta_min": float(grid.theta_min),
        "theta_max": float(grid.theta_max),
        "phi_min": float(grid.phi_min),
        "phi_max": float(grid.phi_max),
        VERSION_ATTR: __version__,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "Conventions": "CF-1.8",
    }
    if scene is not None:
        all_attrs["scene"] = scene
    for key, value in (attrs or {}).items():
        all_attrs[key] = value
    coords = {
        "theta": ("theta", grid.theta, {"units": "rad", "long_name": "polar angle from -z at the focus"}),
        "phi": ("phi", grid.phi, {"units": "rad", "long_name": "azimuth atan2(y, x) at the focus"}),
    }
    return xr.Dataset(data_vars, coords=coords, attrs=all_attrs)


def grid_of(ds: xr.Dataset) -> SphereGrid:
    """The :class:`SphereGrid` of a FieldMap, from its coordinates and attributes alone."""
    grid = SphereGrid.from_centres(ds["theta"].values, ds["phi"].values, ds.attrs["sphere_radius"])
    if all(k in ds.attrs for k in ("theta_min", "theta_max", "phi_min", "phi_max")):
        # the edges recorded by the producer; they matter for a single row or column
        grid = SphereGrid(grid.radius, grid.n_theta, grid.n_phi,
                          float(ds.attrs["theta_min"]), float(ds.attrs["theta_max"]),
                          float(ds.attrs["phi_min"]), float(ds.attrs["phi_max"]))
    return grid


def canonical(ds: xr.Dataset, source: str = "FieldMap") -> xr.Dataset:
    """``ds`` in the contract's canonical order: dims (theta, phi) in that order, both
    coordinates ascending (a legal NetCDF file may store either descending, or the variables
    transposed; every reader then sees the same arrays)."""
    return canonical_order(ds, ("theta", "phi"), "rad", source, FieldMapError)


def validate(ds: xr.Dataset, source: str = "FieldMap") -> xr.Dataset:
    """Check ``ds`` against the contract and return it in canonical order (:func:`canonical`);
    raise :class:`FieldMapError` naming the first defect."""
    ds = canonical(ds, source)
    for coord in ("theta", "phi"):
        if ds[coord].attrs.get("units", "rad") != "rad":
            raise FieldMapError(f"{source}: coordinate '{coord}' must be in rad, "
                                f"got {ds[coord].attrs.get('units')!r}")
        values = np.asarray(ds[coord].values, dtype=np.float64)
        if values.size > 1 and not np.allclose(np.diff(values), values[1] - values[0],
                                               rtol=1e-6, atol=1e-12):
            raise FieldMapError(f"{source}: coordinate '{coord}' must be regularly spaced")
    if float(np.min(ds["theta"].values)) < 0.0:
        raise FieldMapError(f"{source}: theta below 0 is not a polar angle from -z")
    if float(np.max(ds["theta"].values)) > np.pi / 2 + 1e-9:
        raise FieldMapError(f"{source}: theta beyond 90 deg is off the hemisphere facing the dish")
    phi = np.asarray(ds["phi"].values, dtype=np.float64)
    if phi.size > 1 and phi[-1] - phi[0] >= 2 * np.pi:
        raise FieldMapError(f"{source}: phi spans more than 360 deg")
    _check_edges(ds, source)
    for name in REQUIRED_VARS:
        if name not in ds.data_vars:
            raise FieldMapError(f"{source}: missing variable '{name}'")
    for name in (*REQUIRED_VARS, "intensity_std", "blocked"):
        if name not in ds.data_vars:
            continue
        if ds[name].dims != ("theta", "phi"):
            raise FieldMapError(f"{source}: variable '{name}' must have dims (theta, phi), "
                                f"got {ds[name].dims}")
        if name == "blocked":
            if not np.all(np.isin(np.asarray(ds[name].values), (0, 1))):
                raise FieldMapError(f"{source}: variable 'blocked' must hold 0 or 1 per cell")
            continue
        _check_units(ds[name].attrs, name, source)
        _check_intensity(ds[name].values, name, source)
    ideal = np.asarray(ds["intensity_ideal"].values, dtype=np.float64)
    if not np.any(ideal > 0.0):  # single zero cells are missing samples to the solver; all is none
        raise FieldMapError(f"{source}: no ideal intensity: variable 'intensity_ideal' holds no "
                            "value > 0 (every cell zero or missing), nothing to compare with")
    for name in ("focal_length", "diameter", "sphere_radius"):
        if name not in ds.attrs:
            raise FieldMapError(f"{source}: missing attribute '{name}' (m)")
        value = _float_attr(ds, name, source)
        if not (value > 0 and np.isfinite(value)):
            raise FieldMapError(f"{source}: attribute '{name}' must be a finite length > 0 m, "
                                f"got {value}")
    for name in ("frequency_hz", "method", "sampling"):
        if name not in ds.attrs:
            raise FieldMapError(f"{source}: missing attribute '{name}'")
    frequency = _float_attr(ds, "frequency_hz", source)
    if not (frequency > 0 and np.isfinite(frequency)):
        raise FieldMapError(f"{source}: attribute 'frequency_hz' must be a finite frequency > 0 Hz, "
                            f"got {frequency}")
    if not MIN_FREQUENCY_HZ <= frequency <= MAX_FREQUENCY_HZ:
        raise FieldMapError(f"{source}: attribute 'frequency_hz' = {frequency:g} Hz is outside "
                            f"{MIN_FREQUENCY_HZ:g} .. {MAX_FREQUENCY_HZ:g} Hz (1 MHz .. 10 THz)")
    if ds.attrs["method"] not in METHODS:
        raise FieldMapError(f"{source}: attribute 'method' must be one of {', '.join(METHODS)}, "
                            f"got {ds.attrs['method']!r}")
    if ds.attrs["sampling"] not in SAMPLINGS:
        raise FieldMapError(f"{source}: attribute 'sampling' must be one of {', '.join(SAMPLINGS)}, "
                            f"got {ds.attrs['sampling']!r}")
    if _float_attr(ds, "sphere_radius", source) >= _float_attr(ds, "focal_length", source):
        raise FieldMapError(f"{source}: sphere_radius must be smaller than focal_length")
    for name in ANGLE_ATTRS:  # optional; the refinement's models read them as numbers
        if name in ds.attrs and not np.isfinite(_float_attr(ds, name, source)):
            raise FieldMapError(f"{source}: attribute '{name}' must be a finite angle (rad)")
    return ds


#: optional attributes, angles in rad: the source's direction and polarisation
ANGLE_ATTRS = ("polarization", "incidence_theta", "incidence_phi")


def _check_edges(ds: xr.Dataset, source: str) -> None:
    """Where the producer recorded the grid's edges (``theta_min`` ... ``phi_max``, rad), the
    coordinates must be the cell centres between them: every reader builds the grid from the
    edges (:func:`grid_of`), so a map cut with xarray that kept the old edges would be read
    stretched over them."""
    for coord in ("theta", "phi"):
        lo, hi = f"{coord}_min", f"{coord}_max"
        if lo not in ds.attrs or hi not in ds.attrs:
            continue
        a, b = _float_attr(ds, lo, source), _float_attr(ds, hi, source)
        values = np.asarray(ds[coord].values, dtype=np.float64)
        n = values.size
        if not (np.isfinite(a) and np.isfinite(b) and b > a) or n == 0:
            raise FieldMapError(f"{source}: attributes '{lo}' and '{hi}' must be finite angles "
                                f"(rad) with {lo} < {hi}")
        step = (b - a) / n
        centres = a + (np.arange(n) + 0.5) * step
        if not np.allclose(values, centres, rtol=0.0, atol=1e-3 * step):
            raise FieldMapError(f"{source}: coordinate '{coord}' is not the {n} cell centres between "
                                f"the attributes {lo} = {a:g} and {hi} = {b:g} rad (a map cut "
                                f"or moved after it was written: set {lo} and {hi} to its new edges)")


#: the ``units`` an intensity may carry: "1" (dimensionless, what every producer writes) or
#: none; anything else (dB, W, mW) is a scale the solver would take for a relative power
INTENSITY_UNITS = ("1", "")


def _check_units(attrs: Mapping[str, Any], name: str, source: str) -> None:
    """An intensity's ``units``: absent, "1" or "" (a linear power relative to the incident
    plane wave, or a measured scan's linear reading whose gain the inversion estimates)."""
    if "units" not in attrs:
        return
    units = attrs["units"]
    if isinstance(units, bytes):
        units = units.decode("utf-8", "replace")
    if isinstance(units, int | float | np.number) and not isinstance(units, bool) and units == 1:
        return
    if isinstance(units, str) and units.strip() in INTENSITY_UNITS:
        return
    raise FieldMapError(f"{source}: variable '{name}' has units {units!r}, expected '1' or none: "
                        "a FieldMap's intensities are linear powers relative to the incident "
                        "plane wave (convert dB with 10**(dB/10); divide a power in W by the "
                        "incident power)")


def _check_intensity(values: np.ndarray, name: str, source: str) -> None:
    """Intensities are |E|^2: real, finite and >= 0 where present (NaN marks a missing
    sample)."""
    arr = np.asarray(values)
    check_real(arr, name, source, FieldMapError, "an intensity")
    arr = arr.astype(np.float64)
    if np.any(np.isinf(arr)):
        raise FieldMapError(f"{source}: variable '{name}' holds infinite values "
                            "(a missing sample is NaN)")
    present = arr[np.isfinite(arr)]
    if present.size and float(present.min()) < 0.0:
        raise FieldMapError(f"{source}: variable '{name}' holds negative values (down to "
                            f"{float(present.min()):.3g}): an intensity |E|^2 is >= 0")


def save(ds: xr.Dataset, path: str | os.PathLike[str]) -> Path:
    """Write a FieldMap atomically (temporary file + rename) as NetCDF-4."""
    return write_atomic(validate(ds), path, FieldMapError)


def load(path: str | os.PathLike[str]) -> xr.Dataset:
    """Read and check a FieldMap; raise :class:`FieldMapError` with one line if it is unusable."""
    return validate(read(path, FieldMapError), source=str(path))


def _checked(values: np.ndarray, shape: tuple[int, int], name: str) -> np.ndarray:
    """``values`` as float64 of ``shape``; complex or non-numeric values refused, not cast."""
    arr = np.asarray(values)
    check_real(arr, name, "FieldMap", FieldMapError, "an intensity")
    arr = arr.astype(np.float64)
    if arr.shape != shape:
        raise FieldMapError(f"{name} has shape {arr.shape}, the grid is {shape}")
    return arr


def _float_attr(ds: xr.Dataset, name: str, source: str) -> float:
    try:
        return float(ds.attrs[name])
    except (TypeError, ValueError) as exc:
        raise FieldMapError(f"{source}: attribute '{name}' must be a number") from exc
