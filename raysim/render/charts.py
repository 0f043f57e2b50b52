"""2D pictures with matplotlib (Agg, no display): (theta, phi) maps and cuts of a FieldMap,
x-y maps and cuts of a SurfaceMap.

Frames: sphere angles shown in degrees (theta from -z at the focus, phi = atan2(y, x)); the plan
views look down -z with x to the right and y up, the same way for the sphere (radius = theta)
and the aperture (x, y in m), so a feature at azimuth phi sits at the same clock position in both.
Deformations are shown in micrometres.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import xarray as xr
from matplotlib.colors import TwoSlopeNorm
from matplotlib.ticker import MaxNLocator

from raysim.render import backend
from raysim.render.data import (
    UM,
    Quantity,
    deformation_limit,
    error_summary,
    fa,
    field_quantity,
    field_subtitle,
    field_title,
    peak_to_peak,
    rim_theta,
    rms,
    surface_panels,
    surface_subtitle,
    surface_title,
    symmetric_limit,
)

RIM_STYLE = {"color": "black", "linestyle": "--", "linewidth": 0.9}
#: the picture size (px) the one-panel charts' text is laid out for: the report's figures
#: (raysim.render.figures.SIZE), whose text reads on the page at the size of the wide ones';
#: larger and smaller pictures scale it (:func:`fitted_text_scale`)
TEXT_SIZE_FOR = (1400, 1050)


# --- FieldMap --------------------------------------------------------------------------------
def field_map(ds: xr.Dataset, quantity: str | Quantity = "fa", size: tuple[int, int] = (1600, 1200),
              title: str | None = None) -> Any:
    """Figure: a quantity on the sphere (a name of FIELD_QUANTITIES or a Quantity on the map's
    cells) as a plan view (radius = theta, deg) and as a rectangular (phi, theta) map, with the
    rim image dashed."""
    q = quantity if isinstance(quantity, Quantity) else field_quantity(ds, quantity)
    fig = backend.figure(size, fitted_text_scale(size, TEXT_SIZE_FOR))
    fig.suptitle(field_title(ds, title or q.label) + "\n" + field_subtitle(ds), fontsize=12)
    left, right = fig.subplots(1, 2, width_ratios=[1.0, 1.35])
    image = plan_view(left, ds, q)
    left.set_title("plan view from above (radius = theta)")
    phi = np.degrees(ds["phi"].values)
    theta = np.degrees(ds["theta"].values)
    right.pcolormesh(cell_edges(phi), cell_edges(theta), np.ma.masked_invalid(q.values),
                     cmap=colour_map(q.cmap), norm=_norm(q), shading="flat", rasterized=True)
    right.axhline(np.degrees(rim_theta(ds)), **RIM_STYLE, label="rim image")
    right.set_xlabel("phi (deg), atan2(y, x) at the focus")
    right.set_ylabel("theta (deg) from -z at the focus")
    right.set_xlim(cell_edges(phi)[0], cell_edges(phi)[-1])
    right.set_ylim(cell_edges(theta)[0], cell_edges(theta)[-1])
    right.set_xticks(np.arange(0, 361, 45))
    right.legend(loc="upper right", fontsize=9)
    right.set_title("(phi, theta) map; grey: no value")
    fig.colorbar(image, ax=[left, right], label=q.label, shrink=0.8, extend=_extend(q))
    return fig


def plan_view(ax: Any, ds: xr.Dataset, q: Quantity) -> Any:
    """Draw ``q`` on ``ax`` as seen from above: the cell (theta, phi) at radius theta (deg) in
    direction phi; returns the mappable."""
    t = cell_edges(np.degrees(ds["theta"].values))
    p = cell_edges(ds["phi"].values)
    T, P = np.meshgrid(t, p, indexing="ij")
    image = ax.pcolormesh(T * np.cos(P), T * np.sin(P), np.ma.masked_invalid(q.values),
                          cmap=colour_map(q.cmap), norm=_norm(q), shading="flat", rasterized=True)
    rim = np.degrees(rim_theta(ds))
    circle = np.linspace(0, 2 * np.pi, 361)
    ax.plot(rim * np.cos(circle), rim * np.sin(circle), **RIM_STYLE)
    for ring in (30, 60):
        ax.plot(ring * np.cos(circle), ring * np.sin(circle), color="0.5", linewidth=0.5)
        ax.text(ring * np.cos(np.radians(-45)), ring * np.sin(np.radians(-45)), f" {ring}°", fontsize=8,
                color="0.2", va="top")
    ax.set_aspect("equal")
    ax.set_xlabel("theta cos(phi) (deg), towards +x")
    ax.set_ylabel("theta sin(phi) (deg), towards +y")
    return image


def field_cut(ds: xr.Dataset, size: tuple[int, int] = (1600, 1200),
              phis_deg: tuple[float, ...] = (0.0, 90.0, 180.0, 270.0)) -> Any:
    """Figure: intensity (deformed and ideal) and FA against theta along cuts of constant phi
    (the cells nearest ``phis_deg``)."""
    fig = backend.figure(size, fitted_text_scale(size, TEXT_SIZE_FOR))
    fig.suptitle(field_title(ds, "Cuts of constant phi") + "\n" + field_subtitle(ds), fontsize=12)
    top, bottom = fig.subplots(2, 1, sharex=True)
    theta = np.degrees(ds["theta"].values)
    phi = np.degrees(ds["phi"].values)
    ratio = fa(ds)
    intensity, ideal = ds["intensity"].values, ds["intensity_ideal"].values
    colours = ["C0", "C1", "C2", "C3", "C4", "C5"]
    # the cells nearest the asked azimuths, each once (a coarse map may have one cell for two)
    columns = dict.fromkeys(int(np.argmin(np.abs((phi - target + 180.0) % 360.0 - 180.0)))
                            for target in phis_deg)
    # a few rows: points marked, so a single row still shows
    style = {"marker": "o", "markersize": 4} if theta.size < 20 else {}
    for k, j in enumerate(columns):
        c = colours[k % len(colours)]
        # a curve is listed in the legend only when it has something to draw
        if np.isfinite(intensity[:, j]).any():
            top.plot(theta, intensity[:, j], color=c, label=f"deformed, phi = {phi[j]:.1f}°", **style)
        if np.isfinite(ideal[:, j]).any():
            top.plot(theta, ideal[:, j], color=c, linestyle=":", linewidth=1.0, **style)
        if np.isfinite(ratio[:, j]).any():
            bottom.plot(theta, ratio[:, j], color=c, label=f"phi = {phi[j]:.1f}°", **style)
    if np.isfinite(ideal[:, list(columns)]).any():
        top.plot([], [], color="0.3", linestyle=":", label="ideal (dotted)")
    top.set_ylabel("intensity |E|² / |E_inc|²")
    if top.get_legend_handles_labels()[0]:
        top.legend(fontsize=9, ncol=2)
    bottom.set_ylabel("FA = I_ideal / I_def - 1")
    limit = symmetric_limit(ratio, 99.5)
    bottom.set_ylim(-1.3 * limit, 1.3 * limit)
    # the rim image, where the scan covers it (a cut of a scan that stops short says so)
    from raysim.maps.fieldmap import grid_of

    rim = float(np.degrees(rim_theta(ds)))
    grid = grid_of(ds)
    covered = np.degrees(grid.theta_min) <= rim <= np.degrees(grid.theta_max)
    if covered:
        for ax in (top, bottom):
            ax.axvline(rim, **RIM_STYLE)
    bottom.set_xlabel("theta (deg) from -z at the focus; "
                      + ("dashed: rim image" if covered else f"rim image at {rim:.2f}°, beyond the scan"))
    if bottom.get_legend_handles_labels()[0]:
        bottom.legend(fontsize=9, ncol=2)
    else:
        bottom.text(0.5, 0.5, "no FA value on these cuts", transform=bottom.transAxes, ha="center",
                    va="center", color="0.3")
    return fig


# --- SurfaceMap ------------------------------------------------------------------------------
def surface_map(ds: xr.Dataset, size: tuple[int, int] = (1600, 1200), text_scale: float = 1.0) -> Any:
    """Figure: the deformation (µm) over the aperture; with a truth, truth / recovered / error
    side by side (truth and recovered on one colour scale), each with its RMS. ``text_scale``:
    text and lines that many times larger (:func:`backend.figure`)."""
    panels = surface_panels(ds)
    fig = backend.figure(size, fitted_text_scale(size, (2400, 1000) if len(panels) > 1 else TEXT_SIZE_FOR,
                                                 text_scale))
    # the layout measures the colour bars' labels a few pixels short (µ's descender): 1.5 % of
    # the height kept free below them; and with equal-aspect maps it leaves the middle panel's
    # title under the suptitle unless the rows keep more room between them
    fig.get_layout_engine().set(rect=(0.0, 0.015, 1.0, 0.985), h_pad=0.15)
    summary = error_summary(ds)
    fig.suptitle(surface_title(ds) + "\n" + surface_subtitle(ds) + (f"\n{summary}" if summary else ""),
                 fontsize=12)
    axes = np.atleast_1d(fig.subplots(1, len(panels)))
    shared = deformation_limit(np.concatenate([v.ravel() for n, v in panels if n != "error"]))
    x, y = ds["x"].values, ds["y"].values
    for ax, (name, values) in zip(axes, panels, strict=True):
        limit = deformation_limit(values) if name == "error" else shared
        image = ax.pcolormesh(cell_edges(x), cell_edges(y), np.ma.masked_invalid(values * UM), cmap="RdBu_r",
                              vmin=-limit, vmax=limit, shading="flat", rasterized=True)
        rim_circle(ax, aperture_radius(ds))
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(f"{name}: RMS {rms(values) * UM:.4g} µm, p-v {peak_to_peak(values) * UM:.4g} µm",
                     fontsize=11)
        if len(panels) == 1:
            bar = fig.colorbar(image, ax=ax, label=f"{name} delta along z (µm)", shrink=0.8)
            centre_group(fig, [ax, bar.ax])
        else:
            bar = fig.colorbar(image, ax=ax, orientation="horizontal", label=f"{name} delta along z (µm)",
                               shrink=0.9, pad=0.08)
            bar.ax.xaxis.set_major_locator(MaxNLocator(nbins=4, steps=[1, 2, 2.5, 5, 10]))  # apart
    return fig


def centre_group(fig: Any, axes: list[Any], pad: float = 0.02) -> None:
    """Narrow the figure's layout to what ``axes`` (a map and its colour bar) take, centred.

    An equal-aspect map in a picture wider than it needs is as high as the picture allows and
    no wider; its colour bar pulls it to the right (matplotlib anchors the parent at the bar),
    so a wide picture (1400 x 600 px) of a measured SurfaceMap, one panel, was two-thirds blank
    on the left. Measured from a layout pass (text sizes included), then laid out again in a
    frame of that width plus ``pad`` (a fraction of the picture's width) on each side, and the
    frame moved by what is still uneven (the map keeps to the bar's side of its frame).
    """
    def extent() -> tuple[float, float]:  # the group's left and right edges (px)
        fig.draw_without_rendering()
        return (min(ax.get_tightbbox().x0 for ax in axes), max(ax.get_tightbbox().x1 for ax in axes))

    engine = fig.get_layout_engine()
    _, bottom, _, height = engine.get()["rect"]
    width = fig.bbox.width
    left, right = extent()
    used = (right - left) / width + 2 * pad
    if used >= 0.98:  # the group fills the picture already
        return
    x0 = (1.0 - used) / 2
    engine.set(rect=(x0, bottom, used, height))
    left, right = extent()
    # a shift keeps the layout inside the frame as it is: move it by half the imbalance
    x0 += ((width - right) - left) / 2 / width
    engine.set(rect=(min(max(x0, 0.0), 1.0 - used), bottom, used, height))


def surface_cut(ds: xr.Dataset, size: tuple[int, int] = (1600, 1200)) -> Any:
    """Figure: profiles (µm) along the x axis (y = 0) and the y axis (x = 0): recovered, truth
    and error when a truth exists."""
    panels = dict(surface_panels(ds))
    fig = backend.figure(size, fitted_text_scale(size, TEXT_SIZE_FOR))
    summary = error_summary(ds)
    fig.suptitle(surface_title(ds, "Surface deformation along cuts") + "\n" + surface_subtitle(ds)
                 + (f"\n{summary}" if summary else ""), fontsize=12)
    axes = fig.subplots(2, 1, sharex=True)
    x, y = ds["x"].values, ds["y"].values
    cuts = (("along the x axis (y = 0)", x, lambda v: profile_at_zero(v, y, axis=0), "x (m)"),
            ("along the y axis (x = 0)", y, lambda v: profile_at_zero(v, x, axis=1), "y (m)"))
    for ax, (title, coord, take, axis) in zip(axes, cuts, strict=True):
        recovered = panels.get("recovered", panels.get("deformation"))
        name = "recovered" if "truth" in panels else "deformation"
        handles = ax.plot(coord, take(recovered) * UM, color="C0", label=name)
        if "truth" in panels:
            handles += ax.plot(coord, take(panels["truth"]) * UM, color="C3", linestyle="--", label="truth")
            # the error on its own scale (right), so a small error stays readable
            right = ax.twinx()
            error = take(panels["error"]) * UM
            handles += right.plot(coord, error, color="0.35", linewidth=1.0, label="error (right scale)")
            limit = 1.2 * deformation_limit(error / UM)
            right.set_ylim(-limit, limit)
            right.set_ylabel("error (µm)", color="0.35")
            right.tick_params(axis="y", colors="0.35")
        ax.axhline(0.0, color="0.6", linewidth=0.6)
        ax.set_title(title, fontsize=11)
        ax.set_ylabel("delta along z (µm)")
        ax.grid(True, alpha=0.3)
        ax.legend(handles=handles, fontsize=9, loc="upper right")
        ax.set_xlabel(axis)
    return fig


# --- helpers ---------------------------------------------------------------------------------
def fitted_text_scale(size: tuple[int, int], reference: tuple[int, int], text_scale: float = 1.0) -> float:
    """Text scale for a figure of ``size`` px whose text is laid out for ``reference`` px: text
    grows and shrinks with the picture (the smaller of the two ratios, not below 0.6, where
    it would stop being legible), times ``text_scale``."""
    ratio = min(size[0] / reference[0], size[1] / reference[1])
    return float(np.clip(max(ratio, 0.6) * text_scale, 0.25, 8.0))


def profile_at_zero(values: np.ndarray, coord: np.ndarray, axis: int) -> np.ndarray:
    """The profile of ``values`` (y, x) at ``coord`` = 0 along ``axis``, linear between the
    two grid lines either side (NaN where either is NaN)."""
    k = int(np.clip(np.searchsorted(coord, 0.0) - 1, 0, len(coord) - 2))
    w = (0.0 - coord[k]) / (coord[k + 1] - coord[k])
    a, b = np.take(values, k, axis=axis), np.take(values, k + 1, axis=axis)
    return (1.0 - w) * a + w * b


def cell_edges(centres: np.ndarray) -> np.ndarray:
    """Cell edges of regularly spaced cell centres."""
    centres = np.asarray(centres, dtype=np.float64)
    if centres.size == 1:
        return np.array([centres[0] - 0.5, centres[0] + 0.5])
    step = (centres[-1] - centres[0]) / (centres.size - 1)
    return np.concatenate([[centres[0] - 0.5 * step], centres + 0.5 * step])


def colour_map(name: str) -> Any:
    import matplotlib

    return matplotlib.colormaps[name].with_extremes(bad="#b0b0b0")


def _norm(q: Quantity) -> Any:
    if q.diverging:
        return TwoSlopeNorm(vcenter=0.0, vmin=q.clim[0], vmax=q.clim[1])
    from matplotlib.colors import Normalize

    return Normalize(vmin=q.clim[0], vmax=q.clim[1])


def _extend(q: Quantity) -> str:
    finite = q.values[np.isfinite(q.values)]
    if finite.size == 0:
        return "neither"
    low, high = finite.min() < q.clim[0], finite.max() > q.clim[1]
    return {(True, True): "both", (True, False): "min", (False, True): "max"}.get((low, high), "neither")


def rim_circle(ax: Any, radius: float) -> None:
    """Draw the aperture's rim, a circle of ``radius`` (m) about the axis."""
    circle = np.linspace(0, 2 * np.pi, 361)
    ax.plot(radius * np.cos(circle), radius * np.sin(circle), color="black", linewidth=0.8)


def aperture_radius(ds: xr.Dataset) -> float:
    """D/2 (m) of a SurfaceMap: its ``diameter`` attribute, else its largest |x|."""
    if "diameter" in ds.attrs:
        return 0.5 * float(ds.attrs["diameter"])
    return float(np.abs(ds["x"].values).max())
