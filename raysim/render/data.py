"""What a picture shows: reading FieldMaps and SurfaceMaps, the quantities, their labels.

Frames and units (docs/physics.md): a FieldMap holds intensities relative to the incident plane
wave on (theta, phi) cells of the sphere of radius R about the focus (rad); a SurfaceMap holds
delta along z (m) on the aperture grid (x, y) (m), NaN outside the aperture. Pictures show
angles in degrees and deformations in micrometres; these conversions happen here.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from raysim.errors import FieldMapError
from raysim.maps.netcdf import read
from raysim.maps.sphere import ideal_go_cell_mean, ideal_go_intensity, theta_rim
from raysim.render.backend import RenderError

FIELD_QUANTITIES = ("fa", "intensity", "normalized")
UM = 1e6  # micrometres per metre


@dataclass(frozen=True)
class Quantity:
    """A field quantity on the sphere cells: values (n_theta, n_phi), label, colours, limits."""

    name: str
    values: NDArray[np.float64]
    label: str
    cmap: str
    clim: tuple[float, float]
    diverging: bool
    short: str = ""


def open_map(path: str | os.PathLike[str]) -> tuple[str, xr.Dataset]:
    """Read a NetCDF file and say which contract it follows: ``("field" | "surface", dataset)``.

    Raises :class:`RenderError` (one line) for a missing, unreadable or unknown file.
    """
    loaded = read(path, RenderError)
    kind = kind_of(loaded, str(path))
    return kind, canonical_order(loaded, kind, str(path))


def canonical_order(ds: xr.Dataset, kind: str, source: str) -> xr.Dataset:
    """The map in its contract's canonical order (ascending coordinates, dims (theta, phi) or
    (y, x)), whatever order the file stored it in."""
    from raysim.maps.fieldmap import canonical as field_canonical
    from solver.errors import SurfaceMapError
    from solver.surface import canonical as surface_canonical

    try:
        return field_canonical(ds, source) if kind == "field" else surface_canonical(ds, source)
    except (FieldMapError, SurfaceMapError) as exc:
        raise RenderError(str(exc)) from exc


def kind_of(ds: xr.Dataset, source: str = "dataset") -> str:
    """``field`` for a FieldMap, ``surface`` for a SurfaceMap; RenderError for anything else."""
    if "intensity" in ds.data_vars and "theta" in ds.coords:
        from raysim.maps.fieldmap import validate

        try:
            validate(ds, source)
        except FieldMapError as exc:
            raise RenderError(str(exc)) from exc
        return "field"
    if "deformation" in ds.data_vars and "x" in ds.coords and "y" in ds.coords:
        from solver.surface import canonical

        check_surface(canonical(ds, source), source)
        return "surface"
    raise RenderError(f"{source}: neither a FieldMap (theta, phi, intensity) nor a SurfaceMap "
                      "(x, y, deformation)")


def check_surface(ds: xr.Dataset, source: str = "SurfaceMap") -> None:
    """The parts of the SurfaceMap contract a picture relies on; RenderError otherwise."""
    for name in ("deformation", "truth", "error"):
        if name in ds.data_vars:
            if ds[name].dims != ("y", "x"):
                raise RenderError(f"{source}: variable '{name}' must have dims (y, x), got {ds[name].dims}")
            if ds[name].attrs.get("units", "m") != "m":
                raise RenderError(f"{source}: variable '{name}' must be in m, "
                                  f"got {ds[name].attrs.get('units')!r}")
    for coord in ("x", "y"):
        if ds[coord].attrs.get("units", "m") != "m":
            raise RenderError(f"{source}: coordinate '{coord}' must be in m")
    for name in ("deformation", "truth", "error"):
        if name in ds.data_vars:
            require_finite(ds[name].values, f"{source}: '{name}'")
    if "focal_length" in ds.attrs and not float(ds.attrs["focal_length"]) > 0:
        raise RenderError(f"{source}: attribute 'focal_length' must be > 0 m")


# --- FieldMap quantities ---------------------------------------------------------------------
def fa(ds: xr.Dataset) -> NDArray[np.float64]:
    """FA = I_ideal / I_def - 1 per cell (:func:`solver.equation.intensity_ratio_fa`); NaN where
    either is missing, I_def <= 0, or the ideal reflector sends nothing (nothing to compare)."""
    from solver.equation import intensity_ratio_fa

    i_ideal = ds["intensity_ideal"].values.astype(np.float64)
    out = intensity_ratio_fa(ds["intensity"].values, i_ideal)
    out[~(i_ideal > 0)] = np.nan
    return out


def ideal_law(ds: xr.Dataset) -> NDArray[np.float64]:
    """The smooth ideal paraboloid's GO intensity (rho/R)^2 on the map's cells, from attributes.

    Cell means for ``sampling = cell_mean``, centre values otherwise; 0 beyond the rim image.
    """
    from raysim.maps.fieldmap import grid_of

    grid = grid_of(ds)
    F, R, D = (float(ds.attrs[k]) for k in ("focal_length", "sphere_radius", "diameter"))
    if ds.attrs.get("sampling") == "cell_mean":
        e = grid.theta_edges
        law = ideal_go_cell_mean(e[:-1], e[1:], F, R, D)
    else:
        law = ideal_go_intensity(grid.theta, F, R, D)
    return np.repeat(law[:, None], grid.n_phi, axis=1)


def field_quantity(ds: xr.Dataset, name: str = "fa") -> Quantity:
    """One of :data:`FIELD_QUANTITIES` on the sphere cells, with its label, colour map and limits.

    - ``fa``: I_ideal / I_def - 1, diverging colours centred on 0 (symmetric robust limits);
    - ``intensity``: |E|^2 relative to the incident wave;
    - ``normalized``: intensity over the smooth ideal GO law (rho/R)^2 (gaps and shadows
      show as dips below 1; NaN beyond the rim image).
    """
    if name == "fa":
        values = fa(ds)
        limit = symmetric_limit(values)
        return Quantity("fa", values, "FA = I_ideal / I_def - 1", "RdBu_r", (-limit, limit), True,
                        "FA = I_ideal/I_def - 1")
    if name == "intensity":
        values = ds["intensity"].values.astype(np.float64)
        finite = values[np.isfinite(values)]
        top = float(finite.max()) if finite.size and finite.max() > 0 else 1.0
        return Quantity("intensity", values, "intensity |E|² / |E_inc|²", "inferno", (0.0, top), False,
                        "|E|²/|E_inc|²")
    if name == "normalized":
        law = ideal_law(ds)
        values = np.full(law.shape, np.nan)
        i_def = ds["intensity"].values.astype(np.float64)
        np.divide(i_def, law, out=values, where=law > 0)
        finite = values[np.isfinite(values)]
        lo = float(np.percentile(finite, 0.5)) if finite.size else 0.0
        hi = float(np.percentile(finite, 99.9)) if finite.size else 1.0
        lo, hi = min(lo, 0.99), max(hi, 1.01)
        return Quantity("normalized", values, "I / (rho/R)², intensity over the ideal GO law", "cividis",
                        (lo, hi), False, "I / (rho/R)²")
    raise RenderError(f"unknown quantity {name!r}: use one of {', '.join(FIELD_QUANTITIES)}")


def symmetric_limit(values: NDArray[np.float64], percentile: float = 99.0, fallback: float = 1.0) -> float:
    """Colour limit L for a diverging map on [-L, L]: a high percentile of |values|, > 0.

    ``fallback`` (in the unit of ``values``) when no value is finite or all are 0."""
    finite = np.abs(values[np.isfinite(values)])
    if finite.size == 0:
        return fallback
    limit = float(np.percentile(finite, percentile))
    if not limit > 0:
        limit = float(finite.max())
    return limit if limit > 0 else fallback


def deformation_limit(values: NDArray[np.float64]) -> float:
    """Colour limit (µm) for deformations ``values`` (m): the round ceiling of their largest
    |value| in micrometres; 1 µm when all are 0 (a flat map)."""
    return nice_ceiling(symmetric_limit(np.asarray(values, dtype=np.float64) * UM, 100.0, 1.0))


def require_finite(values: NDArray[np.float64], what: str) -> None:
    """RenderError (one line) when ``values`` hold no finite number: nothing to draw."""
    if not np.any(np.isfinite(values)):
        raise RenderError(f"{what} holds no finite value: nothing to draw")


def nice_ceiling(value: float) -> float:
    """The smallest of 1, 1.2, 1.5, 2, 2.5, 3, 4, 5, 6, 7, 8 x 10^n not below ``value`` (> 0)."""
    if not value > 0 or not np.isfinite(value):
        return 1.0
    power = 10.0 ** np.floor(np.log10(value))
    for step in (1.0, 1.2, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0):
        if step * power >= value * (1 - 1e-12):
            return float(step * power)
    return float(10.0 * power)  # pragma: no cover - the loop ends at 10


def rim_theta(ds: xr.Dataset) -> float:
    """theta (rad) of the rim image, 2 atan(D / 4F), from the map's attributes."""
    return theta_rim(float(ds.attrs["diameter"]), float(ds.attrs["focal_length"]))


# --- labels ----------------------------------------------------------------------------------
def frequency_text(hz: float) -> str:
    """A frequency for a title: 0.30 GHz, 850 MHz."""
    if not np.isfinite(hz) or hz <= 0:
        return "frequency unknown"
    return f"{hz / 1e9:.2f} GHz" if hz >= 1e8 else f"{hz / 1e6:.0f} MHz"


def method_text(method: str) -> str:
    return {"go": "GO", "po": "PO", "po+ptd": "PO+PTD", "go+edge": "GO+edge",
            "measured": "measured scan"}.get(method, method)


def field_title(ds: xr.Dataset, what: str) -> str:
    """``what`` with the scene, method and frequency of a FieldMap."""
    name = ds.attrs.get("scene_name") or ""
    parts = [what, method_text(str(ds.attrs.get("method", "?"))),
             frequency_text(float(ds.attrs.get("frequency_hz", np.nan)))]
    if name:
        parts.insert(1, str(name))
    return " — ".join([parts[0], ", ".join(parts[1:])])


def field_subtitle_lines(ds: xr.Dataset) -> list[str]:
    """Geometry of a FieldMap: [D, F and R; the grid and the rim image]."""
    from raysim.maps.fieldmap import grid_of

    D, F, R = (float(ds.attrs[k]) for k in ("diameter", "focal_length", "sphere_radius"))
    grid = grid_of(ds)
    dt, dp = np.degrees(grid.dtheta), np.degrees(grid.dphi)
    steps = f"{dt:.2g}°" if np.isclose(dt, dp, rtol=1e-3) else f"{dt:.2g}° in theta x {dp:.2g}° in phi"
    return [f"D = {D:g} m, F = {F:g} m, sphere R = {R:g} m about the focus",
            f"{grid.n_theta} x {grid.n_phi} cells ({steps}), rim image at theta = "
            f"{np.degrees(rim_theta(ds)):.2f}°"]


def field_subtitle(ds: xr.Dataset) -> str:
    """Geometry line: D, F, R and the grid of a FieldMap."""
    return ", ".join(field_subtitle_lines(ds))


def surface_title(ds: xr.Dataset, what: str = "Surface deformation") -> str:
    """``what`` with the solver and the data it came from (method, frequency)."""
    parts = [what]
    details = []
    if ds.attrs.get("solver"):
        details.append(f"solver {ds.attrs['solver']}")
    method = ds.attrs.get("data_method") or ds.attrs.get("method")
    if method:
        details.append(f"{method_text(str(method))} data")
    hz = ds.attrs.get("data_frequency_hz", ds.attrs.get("frequency_hz"))
    if hz is not None and float(hz) > 0:
        details.append(frequency_text(float(hz)))
    if details:
        parts.append(", ".join(details))
    return " — ".join(parts)


def surface_subtitle(ds: xr.Dataset) -> str:
    """Boundary assumption and removed terms of a SurfaceMap (what the solve assumed)."""
    bits = []
    if ds.attrs.get("boundary"):
        bits.append(f"boundary: {ds.attrs['boundary']}")
    removed = str(ds.attrs.get("removed_terms", "") or "none")
    bits.append(f"removed: {removed}")
    n = ds.sizes["x"]
    x = ds["x"].values
    step = float(x[1] - x[0]) if n > 1 else np.nan
    bits.append(f"grid {ds.sizes['y']} x {n}, step {step:.3g} m")
    return "; ".join(bits)


# --- SurfaceMap statistics -------------------------------------------------------------------
def rms(values: NDArray[np.float64]) -> float:
    """Root mean square (same unit) over the finite points (inside the aperture)."""
    finite = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(finite * finite))) if finite.size else float("nan")


def peak_to_peak(values: NDArray[np.float64]) -> float:
    finite = values[np.isfinite(values)]
    return float(finite.max() - finite.min()) if finite.size else float("nan")


def surface_panels(ds: xr.Dataset) -> list[tuple[str, NDArray[np.float64]]]:
    """The maps a surface picture shows: [("recovered", delta)] or truth, recovered, error (m)."""
    delta = ds["deformation"].values.astype(np.float64)
    if "truth" not in ds.data_vars:
        return [("deformation", delta)]
    truth = ds["truth"].values.astype(np.float64)
    error = ds["error"].values.astype(np.float64) if "error" in ds.data_vars else delta - truth
    return [("truth", truth), ("recovered", delta), ("error", error)]


def error_summary(ds: xr.Dataset) -> str:
    """``RMS error 13.3 µm, RRMS 1.11 %`` from the maps (RRMS = RMS / peak-to-peak of truth)."""
    panels = dict(surface_panels(ds))
    if "error" not in panels:
        return ""
    err = rms(panels["error"])
    M = peak_to_peak(panels["truth"])
    if not M > 0:  # a flat truth: RRMS = RMS / M means nothing
        return f"RMS error {err * UM:.3g} µm; the truth is flat (M = 0 µm), no RRMS"
    return f"RMS error {err * UM:.3g} µm, RRMS {100 * err / M:.3g} % (M = {M * UM:.4g} µm)"
