"""The correction section of the report: before / after maps with the panel outlines and the
actuators, the commands as coloured dots, and their table.

Frame: the aperture plane (x, y) in m; maps and commands in µm (a positive command moves the
surface along +z, toward the focus: :mod:`solver.correction`). Cells the obstacles hide from the
scan (the FieldMap's ``blocked`` sphere cells, carried to the aperture through the ideal GO
mapping theta = 2 atan(r / 2F), phi = atan2(y, x)) are masked grey: the map there is
interpolated, not measured.
"""

from __future__ import annotations

import html
from typing import Any

import numpy as np
import xarray as xr

from raysim.render import backend
from raysim.render.charts import cell_edges, colour_map, rim_circle
from raysim.render.data import UM, deformation_limit, nice_ceiling


def blocked_on_aperture(field: xr.Dataset, x: np.ndarray) -> np.ndarray | None:
    """Aperture cells (len(x), len(x)) whose ideal-GO image on the sphere is a ``blocked`` cell;
    None when the FieldMap has no obstacles."""
    if "blocked" not in field.data_vars:
        return None
    F = float(field.attrs["focal_length"])
    X, Y = np.meshgrid(x, x)
    theta = 2.0 * np.arctan(np.hypot(X, Y) / (2.0 * F))
    phi = np.mod(np.arctan2(Y, X), 2.0 * np.pi)
    t, p = field["theta"].values, field["phi"].values
    it = np.clip(np.searchsorted(t, theta) - 1, 0, len(t) - 1)
    # nearest cell centre
    it = np.where((it + 1 < len(t)) & (np.abs(t[np.minimum(it + 1, len(t) - 1)] - theta)
                                       < np.abs(t[it] - theta)), it + 1, it)
    ip = np.argmin(np.abs(np.mod(phi[..., None] - p + np.pi, 2 * np.pi) - np.pi), axis=-1)
    return field["blocked"].values[it, ip].astype(bool)


def panel_outlines(ax: Any, layout) -> None:
    """Draw the ring edges and the radial cuts of a :class:`~raysim.surface.panels.PanelLayout`."""
    circle = np.linspace(0.0, 2.0 * np.pi, 361)
    for r in layout.ring_edges[1:-1]:
        ax.plot(r * np.cos(circle), r * np.sin(circle), color="black", linewidth=0.4)
    for ring in range(layout.n_rings):
        n = layout.panels_per_ring[ring]
        if n < 2:
            continue
        r0, r1 = layout.ring_edges[ring], layout.ring_edges[ring + 1]
        for k in range(n):
            phi = layout.phi0 + k * 2.0 * np.pi / n
            ax.plot([r0 * np.cos(phi), r1 * np.cos(phi)], [r0 * np.sin(phi), r1 * np.sin(phi)],
                    color="black", linewidth=0.4)


def correction_figure(x: np.ndarray, layout, actuators, correction, blocked: np.ndarray | None,
                      unit: str = "µm", size: tuple[int, int] = (2400, 900)) -> Any:
    """Figure: the map before (terms removed), the predicted surface after (one colour scale) and
    the commands as dots coloured by their value, panel outlines and actuators on each."""
    fig = backend.figure(size)
    # equal-aspect maps: the constrained layout sizes the boxes before the aspect shrinks them
    # and puts the titles above the canvas; the compressed layout is made for fixed aspects
    fig.set_layout_engine("compressed")
    axes = fig.subplots(1, 3)
    before, after = correction.before.copy(), correction.after.copy()
    if blocked is not None:
        before[blocked] = np.nan
        after[blocked] = np.nan
    limit = deformation_limit(before)
    edges = cell_edges(x)
    a = float(np.abs(edges).max())
    titles = (f"before: RMS {correction.rms_before * UM:.3g} µm",
              f"after (predicted): RMS {correction.rms_after * UM:.3g} µm")
    for ax, values, title in zip(axes[:2], (before, after), titles, strict=True):
        image = ax.pcolormesh(edges, edges, np.ma.masked_invalid(values * UM), cmap=colour_map("RdBu_r"),
                              vmin=-limit, vmax=limit, shading="flat", rasterized=True)
        ax.set_title(title, fontsize=11)
        fig.colorbar(image, ax=ax, orientation="horizontal", label="delta along z (µm)", shrink=0.9,
                     pad=0.08)
    cmax = nice_ceiling(max(np.max(np.abs(correction.commands)) * UM, 1e-3))
    dots = axes[2].scatter(actuators.xy[:, 0], actuators.xy[:, 1], c=correction.commands * UM,
                           cmap="PuOr_r", vmin=-cmax, vmax=cmax, s=18, edgecolors="black",
                           linewidths=0.3, zorder=3)
    axes[2].set_title(f"commands of {actuators.n_actuators} actuators (+: toward the focus)", fontsize=11)
    fig.colorbar(dots, ax=axes[2], orientation="horizontal", label=f"command ({unit})", shrink=0.9,
                 pad=0.08)
    for ax in axes:
        panel_outlines(ax, layout)
        rim_circle(ax, layout.rim_radius)
        if ax is not axes[2]:
            ax.plot(actuators.xy[:, 0], actuators.xy[:, 1], ".", color="black", markersize=2)
        ax.set_xlim(-a, a)
        ax.set_ylim(-a, a)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    return fig


def command_table_html(actuators, correction, frequencies=(), efficiency=None) -> str:
    """An HTML table of the commands (µm) in a collapsible block, with the RMS figures."""
    shape = html.escape(actuators.shape_description())
    head = (f"<p>Commands from the recovered map: a positive command moves the surface along +z "
            f"(toward the focus) by that many µm. Panels moved as {shape}; "
            f"RMS over the panels {correction.rms_before * UM:.2f} µm before, "
            f"{correction.rms_after * UM:.2f} µm predicted after (rigid-panel floor "
            f"{correction.within_panel_rms * UM:.2f} µm).</p>")
    rows = "".join(
        f"<tr><td>{html.escape(name)}</td><td>{actuators.xy[i, 0]:.3f}</td><td>{actuators.xy[i, 1]:.3f}</td>"
        f"<td>{' '.join(str(p) for p in actuators.panels_of(i))}</td>"
        f"<td>{correction.commands[i] * UM:+.3f}</td></tr>"
        for i, name in enumerate(actuators.ids))
    return (head + "<details><summary>command table</summary><table><tr><th>actuator</th><th>x (m)</th>"
            "<th>y (m)</th><th>panels</th><th>command (µm)</th></tr>" + rows + "</table></details>")
