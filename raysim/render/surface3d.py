"""A SurfaceMap in 3D: the dish warped by its deformation, exaggerated, coloured in micrometres.

Reflector frame (docs/physics.md), metres: vertex at the origin, axis +z. The drawn surface is
z = r^2/(4F) + k delta(x, y) over the aperture r <= D/2, with delta along z from the map and k
the exaggeration stated on the picture; without a focal length in the attributes it is the
flat aperture z = k delta. The map's grid values are sampled on a polar mesh (bilinear) so the
rim is a circle, not grid steps. With a truth, truth / recovered / error stand side by side
with one exaggeration; truth and recovered share one colour scale.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import xarray as xr
from scipy.interpolate import RegularGridInterpolator
from scipy.ndimage import distance_transform_edt

from raysim.render import backend
from raysim.render.data import (
    UM,
    deformation_limit,
    error_summary,
    peak_to_peak,
    rms,
    surface_panels,
    surface_subtitle,
    surface_title,
)

RELIEF = 0.06  # exaggerated peak-to-peak as a fraction of D


def exaggeration(values: np.ndarray, D: float) -> float:
    """A round factor k (1, 2 or 5 x 10^n) making k x peak-to-peak(values) about 6 % of D."""
    ptp = peak_to_peak(values)
    if not ptp > 0:
        return 1.0
    target = RELIEF * D / ptp
    power = 10.0 ** math.floor(math.log10(target))
    return max(step * power for step in (1.0, 2.0, 5.0) if step * power <= target)


def aperture_radius_of(ds: xr.Dataset) -> float:
    """D/2 (m): from the ``diameter`` attribute, else the farthest finite grid point."""
    if "diameter" in ds.attrs:
        return 0.5 * float(ds.attrs["diameter"])
    X, Y = np.meshgrid(ds["x"].values, ds["y"].values)
    finite = np.isfinite(ds["deformation"].values)
    return float(np.hypot(X, Y)[finite].max())


def sampler(ds: xr.Dataset, values: np.ndarray) -> RegularGridInterpolator:
    """Bilinear interpolator of ``values`` (y, x) with NaNs filled by their nearest finite value,
    so samples near the rim stay finite."""
    missing = ~np.isfinite(values)
    if missing.any():
        _, (iy, ix) = distance_transform_edt(missing, return_indices=True)
        values = values[iy, ix]
    return RegularGridInterpolator((ds["y"].values, ds["x"].values), values, bounds_error=False,
                                   fill_value=None)


def warped_dish(ds: xr.Dataset, values: np.ndarray, k: float, n_r: int = 160, n_phi: int = 240) -> Any:
    """pyvista StructuredGrid of the dish z = r^2/(4F) + k delta on a polar mesh (m), with the
    point data ``delta_um`` (delta in micrometres)."""
    pv = backend.pyvista()
    a = aperture_radius_of(ds)
    r = np.linspace(0.0, a, n_r)
    phi = np.linspace(0.0, 2.0 * np.pi, n_phi + 1)
    R, P = np.meshgrid(r, phi, indexing="ij")
    X, Y = R * np.cos(P), R * np.sin(P)
    delta = sampler(ds, values)(np.stack([Y.ravel(), X.ravel()], axis=-1)).reshape(X.shape)
    F = float(ds.attrs.get("focal_length", 0.0) or 0.0)
    base = R * R / (4.0 * F) if F > 0 else np.zeros_like(R)
    mesh = pv.StructuredGrid(X, Y, base + k * delta)
    mesh.point_data["delta_um"] = (delta * UM).ravel(order="F")
    return mesh


def surface_plotter(ds: xr.Dataset, size: tuple[int, int] = (2400, 1000), k: float | None = None,
                    title: str | None = None, text_scale: float = 1.0) -> Any:
    """Build (not render) the 3D picture of a SurfaceMap; returns the pyvista Plotter.

    A title strip on top; below it one view of the deformation, or truth / recovered / error
    side by side when the map has a truth (subplots (1, 0), (1, 1), (1, 2)), each with its
    colour bar at the bottom (tick labels above the bar, its title below it). ``k`` is the
    exaggeration (None: chosen by :func:`exaggeration` from the largest shown map);
    ``text_scale`` enlarges every text by that factor (a wide picture shown shrunk to a page's
    width). Tests use the plotter's renderers and cameras to project points to pixels.
    """
    panels = surface_panels(ds)
    a = aperture_radius_of(ds)
    F = float(ds.attrs.get("focal_length", 0.0) or 0.0)
    if k is None:
        k = exaggeration(np.concatenate([v.ravel() for n, v in panels if n != "error"]), 2 * a)
    n = len(panels)
    top = 0.13 if n == 1 else 0.16
    pl = backend.plotter(size, shape=(2, n), row_weights=[top, 1.0 - top], groups=[(0, np.s_[:])])
    scale = min(size[1] / 900.0, size[0] / n / 700.0) * text_scale
    shared = deformation_limit(np.concatenate([v.ravel() for n, v in panels if n != "error"]))
    title_size, label_size = backend.points(14 * scale), backend.points(13 * scale)
    # VTK draws a colour bar's title on the side of its tick labels, on top of the middle one:
    # the bar's labels go above it and its title, a text of its own, below it (heights as
    # fractions of the panel's viewport; font sizes about pixels)
    view = (1.0 - top) * size[1]
    title_y = 0.015
    bar_y = title_y + 1.3 * title_size / view
    for col, (name, values) in enumerate(panels):
        pl.subplot(1, col)
        limit = deformation_limit(values) if name == "error" else shared
        bar_title = f"{name}: delta along z (µm)"
        bar = {"title": bar_title, "vertical": False, "position_x": 0.15, "position_y": bar_y,
               "width": 0.7, "height": 0.04 + 1.5 * label_size / view, "label_font_size": label_size,
               "color": "black", "n_labels": 5, "fmt": "%.0f" if limit >= 10 else "%.2f"}
        dish = warped_dish(ds, values, k)
        pl.add_mesh(dish, scalars="delta_um", cmap="RdBu_r", clim=[-limit, limit],
                    smooth_shading=True, ambient=0.3, diffuse=0.75, specular=0.1, scalar_bar_args=bar,
                    name=f"dish_{name}")
        scalar_bar = pl.scalar_bars[bar_title]
        scalar_bar.SetTitle("")  # without a title VTK puts the labels above a horizontal bar
        scalar_bar.SetTextPositionToSucceedScalarBar()
        _text(pl, bar_title, title_y, title_size, f"bar_title_{name}", "bottom")
        pl.add_mesh(_guides(a, F, sampler(ds, values), k), color="#505050", line_width=1.0,
                    name=f"guides_{name}")
        pl.add_point_labels(np.array([[1.1 * a, 0.0, _z(1.1 * a, F)], [0.0, 1.1 * a, _z(1.1 * a, F)]]),
                            ["+x", "+y"], font_size=backend.points(14 * scale), text_color="black",
                            shape=None, show_points=False, always_visible=True, name=f"axes_{name}")
        _text(pl, f"{name}: RMS {rms(values) * UM:.4g} µm, p-v {peak_to_peak(values) * UM:.4g} µm",
              0.985, backend.points(15 * scale), f"label_{name}", "top")
        _camera(pl, a, F, 1.35 if n == 1 else 1.15)
    pl.subplot(0, 0)
    lines = [title or surface_title(ds), surface_subtitle(ds)]
    summary = error_summary(ds)
    lines.append(f"height exaggerated {k:g} x (delta along z); rings every {_ring_step(a):g} m"
                 + (f"; {summary}" if summary else ""))
    _text(pl, "\n".join(lines), 0.5, backend.points(14 * size[1] / 900 * text_scale), "title", "centered")
    if n > 1:
        pl.link_views(views=list(range(1, n + 1)))
    return pl


def _text(pl: Any, text: str, y: float, size: int, name: str, align: str) -> Any:
    """Text of ``size`` (about pixels) centred across the active view at height ``y`` (a fraction
    of the view), its ``align`` (top, centered, bottom) edge there."""
    actor = pl.add_text(text, position=(0.5, y), viewport=True, font_size=size / 2,  # pyvista doubles
                        color="black", name=name)
    prop = actor.GetTextProperty()
    prop.SetJustificationToCentered()
    getattr(prop, f"SetVerticalJustificationTo{align.capitalize()}")()
    # shrunk to 96 % of the view's width when wider (a narrow picture or a long line)
    x0, _, x1, _ = pl.renderer.GetViewport()
    room = 0.96 * (x1 - x0) * pl.window_size[0]
    box = [0.0] * 4
    actor.GetBoundingBox(pl.renderer, box)
    if box[1] - box[0] > room:
        prop.SetFontSize(max(7, int(prop.GetFontSize() * room / (box[1] - box[0]))))
    return actor


def _z(r: Any, F: float) -> Any:
    """Height of the ideal surface at radius r (m): r^2/(4F), or 0 without a focal length."""
    return r * r / (4.0 * F) if F > 0 else 0.0 * r


def _ring_step(a: float) -> float:
    """A round radius step (m) giving about five guide rings."""
    raw = a / 5.0
    power = 10.0 ** math.floor(math.log10(raw))
    return max(step * power for step in (1.0, 2.0, 5.0) if step * power <= raw)


def _guides(a: float, F: float, delta: RegularGridInterpolator, k: float) -> Any:
    """Lines on the warped surface (m): rings every :func:`_ring_step` up to the rim and spokes
    every 30 deg, lifted 0.2 % of a above it so the surface does not hide them."""
    pv = backend.pyvista()
    lift = 0.002 * a
    paths = []
    phi = np.linspace(0.0, 2.0 * np.pi, 241)
    for r in [*np.arange(_ring_step(a), a, _ring_step(a)), a]:
        paths.append((np.full(phi.size, r), phi))
    r = np.linspace(0.0, a, 80)
    for angle in np.radians(np.arange(0, 360, 30)):
        paths.append((r, np.full(r.size, angle)))
    pieces = []
    for rr, pp in paths:
        x, y = rr * np.cos(pp), rr * np.sin(pp)
        z = _z(rr, F) + k * delta(np.column_stack([y, x])) + lift
        pieces.append(pv.lines_from_points(np.column_stack([x, y, z])))
    return pv.merge(pieces)


def _camera(pl: Any, a: float, F: float, zoom: float) -> None:
    """Oblique view from the -y side, 35 deg above the aperture plane, the whole dish framed."""
    centre = np.array([0.0, 0.0, 0.45 * _z(a, F)])
    el, az = math.radians(35.0), math.radians(-70.0)
    direction = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    pl.camera.focal_point = tuple(centre)
    pl.camera.position = tuple(centre + direction * a)
    pl.camera.up = (0.0, 0.0, 1.0)
    pl.camera.view_angle = 30.0
    pl.reset_camera()
    pl.camera.zoom(zoom)
