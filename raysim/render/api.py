"""``render``: any FieldMap or SurfaceMap file (or dataset) -> one PNG of a chosen kind.

Kinds: ``3d`` (pyvista off-screen, EGL), ``map`` and ``cut`` (matplotlib). Defaults: a FieldMap
as ``3d`` (hemisphere over the dish), a SurfaceMap as ``map`` (micrometres over the aperture).
Sizes are (width, height) in pixels, at least 1200 x 900 by default.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import xarray as xr

from raysim.render import backend, charts
from raysim.render.backend import RenderError
from raysim.render.data import FIELD_QUANTITIES, field_quantity, kind_of, open_map, require_finite

KINDS = ("3d", "map", "cut")
DEFAULT_KIND = {"field": "3d", "surface": "map"}


def default_size(contract: str, kind: str, panels: int = 1) -> tuple[int, int]:
    """Default picture size (width, height) in pixels for a contract, kind and panel count."""
    if contract == "surface" and kind in ("3d", "map") and panels > 1:
        return (2400, 1000)
    return (1600, 1200)


def render_image(ds: xr.Dataset, kind: str | None = None, size: str | tuple[int, int] | None = None,
                 quantity: str = "fa", contract: str | None = None, source: str = "") -> np.ndarray:
    """The picture of a FieldMap or SurfaceMap dataset as an RGB array (height, width, 3).

    ``quantity`` (fa, intensity, normalized) chooses what colours a FieldMap's ``3d`` and
    ``map`` pictures; the ``cut`` of a FieldMap shows intensity and FA together. A map with no
    finite value to draw is a RenderError (``source`` names it in the message).
    """
    contract = contract or kind_of(ds, source or "dataset")
    source = source or ("FieldMap" if contract == "field" else "SurfaceMap")
    kind = kind or DEFAULT_KIND[contract]
    if kind not in KINDS:
        raise RenderError(f"unknown kind {kind!r}: use one of {', '.join(KINDS)}")
    if quantity not in FIELD_QUANTITIES:
        raise RenderError(f"unknown quantity {quantity!r}: use one of {', '.join(FIELD_QUANTITIES)}")
    panels = 3 if contract == "surface" and "truth" in ds.data_vars else 1
    pixels = backend.parse_size(size, default_size(contract, kind, panels))
    if contract == "field":
        require_finite(ds["intensity"].values, f"{source}: 'intensity'")
        if kind != "cut":
            q = field_quantity(ds, quantity)
            require_finite(q.values, f"{source}: the {q.short} map")
        if kind == "3d":
            from raysim.render.field3d import field_image

            return field_image(ds, quantity, pixels)
        fig = charts.field_map(ds, quantity, pixels) if kind == "map" else charts.field_cut(ds, pixels)
        return backend.figure_image(fig)
    if kind == "3d":
        from raysim.render.surface3d import surface_plotter

        pl = surface_plotter(ds, pixels)
        image = np.array(backend.screenshot(pl, None))
        pl.close()
        return image
    fig = charts.surface_map(ds, pixels) if kind == "map" else charts.surface_cut(ds, pixels)
    return backend.figure_image(fig)


def check_output_name(output: str | os.PathLike[str]) -> Path:
    """The PNG file ``output`` names, before any work: RenderError for a name not ending in
    .png, for a name ending in a slash (it names a folder) and for an existing folder."""
    text = os.fspath(output)
    if text.endswith(("/", os.sep)):
        raise RenderError(f"{text}: ends in a slash, so it names a folder: give a file name")
    path = Path(text)
    if path.suffix.lower() != ".png":
        raise RenderError(f"{path}: the picture is written as PNG, name it *.png")
    if path.is_dir():
        raise RenderError(f"{path}: is a folder, give a file name")
    return path


def render(source: str | os.PathLike[str] | xr.Dataset, output: str | os.PathLike[str],
           kind: str | None = None, size: str | tuple[int, int] | None = None,
           quantity: str | None = None) -> Path:
    """Render a FieldMap or SurfaceMap (a NetCDF path or a dataset) to the PNG ``output``.

    Parameters
    ----------
    source : FieldMap or SurfaceMap, as a file path or an ``xarray.Dataset``.
    output : PNG file to write (its folder is created).
    kind : ``3d``, ``map`` or ``cut``; None picks ``3d`` for a FieldMap, ``map`` for a SurfaceMap.
    size : ``"WxH"`` or (width, height) in pixels; None picks at least 1200 x 900.
    quantity : for a FieldMap only: ``fa`` (I_ideal / I_def - 1, the default), ``intensity`` or
        ``normalized`` (intensity over the ideal GO law (rho/R)^2). Given for a SurfaceMap it is
        a RenderError (a SurfaceMap has one quantity, delta).
    """
    output = check_output_name(output)
    if isinstance(source, xr.Dataset):
        name = "dataset"
        contract, ds = kind_of(source), source
    else:
        name = str(source)
        contract, ds = open_map(source)
    if contract == "surface" and quantity is not None:
        raise RenderError(f"--quantity applies to FieldMaps only; {name} is a SurfaceMap (delta in µm)")
    image = render_image(ds, kind, size, quantity or "fa", contract, name)
    return backend.write_png(image, output)
