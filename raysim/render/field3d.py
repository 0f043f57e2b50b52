"""A FieldMap in 3D: the probe hemisphere coloured by a field quantity, above its reflector.

Reflector frame (docs/physics.md), metres: vertex at the origin, axis +z, focus (0, 0, F). The
hemisphere of radius R about the focus is drawn cell by cell (theta from -z, phi = atan2(y, x)),
each cell one colour (GO maps hold cell means). Below it the reflector: the scene's panels with
their outlines (gaps) when the FieldMap carries a scene, else the ideal paraboloid from the
attributes alone (a measured scan). The focus is a black dot; arrows show the incident plane
wave's direction of travel.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np
import xarray as xr

from raysim.maps.fieldmap import grid_of
from raysim.render import backend
from raysim.render.data import Quantity, field_quantity, field_subtitle_lines, field_title, frequency_text

DISH_CELLS = 70  # triangle edge of the drawn dish: D / DISH_CELLS (coarse; gaps drawn as lines)
NAN_COLOR = "#b0b0b0"


def hemisphere(ds: xr.Dataset, values: np.ndarray) -> Any:
    """The sphere cells of ``ds`` as pyvista PolyData quads (m), ``values`` (n_theta, n_phi) as
    cell data in row-major (theta, phi) order; faces wound so their normals point at the focus."""
    pv = backend.pyvista()
    grid = grid_of(ds)
    F = float(ds.attrs["focal_length"])
    t, p = np.meshgrid(grid.theta_edges, grid.phi_edges, indexing="ij")
    points = np.column_stack([(grid.radius * np.sin(t) * np.cos(p)).ravel(),
                              (grid.radius * np.sin(t) * np.sin(p)).ravel(),
                              (F - grid.radius * np.cos(t)).ravel()])
    n_p = grid.n_phi + 1
    i, j = np.meshgrid(np.arange(grid.n_theta), np.arange(grid.n_phi), indexing="ij")
    a = (i * n_p + j).ravel()
    # (theta, phi) -> (theta, phi + dphi) -> (theta + dtheta, phi + dphi): counter-clockwise
    # seen from the focus, so the front face is the inner face
    quads = np.column_stack([np.full(a.size, 4), a, a + n_p, a + n_p + 1, a + 1])
    mesh = pv.PolyData(points, quads.ravel())
    mesh.cell_data["value"] = np.asarray(values, dtype=np.float64).ravel()
    return mesh


def reflector(ds: xr.Dataset) -> tuple[Any, Any, str]:
    """The reflector to draw under the hemisphere: pyvista PolyData of its triangles and of its
    panel outlines (m), and a description.

    From the FieldMap's scene (panels and gaps as laid out there) when it has one and it can be
    rebuilt here; otherwise the ideal paraboloid z = r^2/(4F) of diameter D from the attributes.
    Drawn coarsely (triangle edge D / DISH_CELLS); the same map draws from a cache.
    """
    text = ds.attrs.get("scene")
    return _reflector(float(ds.attrs["diameter"]), float(ds.attrs["focal_length"]),
                      str(text) if text else None)


@functools.lru_cache(maxsize=4)
def _reflector(D: float, F: float, text: str | None) -> tuple[Any, Any, str]:
    from raysim.surface.mesh import paraboloid

    layout, what = None, "ideal paraboloid (from the map's attributes)"
    from raysim.scene.scene import scene_of

    scene = scene_of({"scene": text})  # None: no scene, or one naming files not present here
    if scene is not None and scene.dish.mesh is None and scene.dish.diameter and scene.dish.focal_length:
        D, F = scene.D, scene.F
        layout = scene.panels
        what = (f"{layout.n_panels} panels, {layout.gap * 1e3:g} mm gaps" if layout is not None
                else "one-piece paraboloid")
    dish = paraboloid(D, F, resolution=D / DISH_CELLS, layout=layout)
    mesh = polydata(dish.vertices, dish.faces)
    edges = mesh.extract_feature_edges(boundary_edges=True, feature_edges=False, manifold_edges=False,
                                       non_manifold_edges=False)
    return mesh, edges, what


def polydata(vertices: np.ndarray, faces: np.ndarray) -> Any:
    """Triangles (m) as pyvista PolyData."""
    pv = backend.pyvista()
    cells = np.column_stack([np.full(len(faces), 3, dtype=np.int64), faces]).ravel()
    return pv.PolyData(np.asarray(vertices, dtype=np.float64), cells)


def source_direction(ds: xr.Dataset) -> np.ndarray:
    """Unit vector along which the incident plane wave travels (on axis: (0, 0, -1))."""
    t = float(ds.attrs.get("incidence_theta", 0.0) or 0.0)
    p = float(ds.attrs.get("incidence_phi", 0.0) or 0.0)
    return -np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


def field_plotter(ds: xr.Dataset, quantity: str = "fa", size: tuple[int, int] = (1600, 1200),
                  show_reflector: bool = True, overview: bool = False) -> Any:
    """Build (not render) the 3D picture of a FieldMap; returns the pyvista Plotter.

    The close-up (default) looks down into the hemisphere from above the rim on the -y side,
    with the reflector's panels around it; ``overview=True`` is the whole antenna from the
    side, without text. Tests use the returned plotter's camera to project points to pixels.
    """
    q = field_quantity(ds, quantity)
    D, F, R = (float(ds.attrs[k]) for k in ("diameter", "focal_length", "sphere_radius"))
    pl = backend.plotter(size)
    t = text_unit(size)
    _add_hemisphere(pl, ds, q, size, bar=not overview)
    what = "no reflector drawn"
    if show_reflector:
        dish, edges, what = reflector(ds)
        pl.add_mesh(dish, color="#cfcfcf", ambient=0.35, diffuse=0.7, specular=0.05,
                    smooth_shading=True, name="reflector")
        if edges.n_cells:
            pl.add_mesh(edges, color="#6e6e6e", line_width=1.0, name="panel_edges")
    _add_focus_and_source(pl, ds, F, R, D, t, labels=not overview)
    if overview:
        _overview_camera(pl, D, F)
        return pl
    w, h = size
    margin = MARGIN * unit(size)
    title = field_title(ds, f"{what_of(q)} on the probe hemisphere").replace(" — ", "\n", 1)
    pixel_text(pl, vtk_text(title), (w / 2, h - margin), 30 * t, "title", "center", "top", w - 2 * margin)
    notes = [f"colour: {vtk_text(q.label)}; grey: no value", *clipping_note(q),
             *field_subtitle_lines(ds), f"reflector: {what}"]
    inset_w, _ = inset_size(size)
    pixel_text(pl, "\n".join(notes), (w - margin, margin), 19 * t, "notes", "right", "bottom",
               w - inset_w - 4 * margin, color="#202020")
    _camera(pl, np.array([0.0, 0.0, F - 0.55 * R]), 0.72 * D, 58.0, -78.0)
    # the scene a little left of the middle, clear of the colour bar (a shift of the picture,
    # in units of half its width)
    pl.camera.SetWindowCenter(0.12 * REFERENCE[0] * unit(size) / w, 0.0)
    return pl


def clipping_note(q: Quantity) -> list[str]:
    """A line saying how many cells lie beyond the colour scale and how far the values reach
    (the bar ends at a percentile and clamps the rest to its end colours); none if no cell does."""
    values = np.asarray(q.values, dtype=np.float64)
    values = values[np.isfinite(values)]
    lo, hi = q.clim
    beyond = np.count_nonzero((values < lo) | (values > hi))
    if not beyond:
        return []
    fmt = _fmt(q.clim)
    return [f"{100 * beyond / values.size:.2g} % of the cells beyond the colour scale, shown in its "
            f"end colours (values {fmt % values.min()} to {fmt % values.max()})"]


def field_image(ds: xr.Dataset, quantity: str = "fa", size: tuple[int, int] = (1600, 1200),
                inset: bool = True) -> np.ndarray:
    """The 3D FieldMap picture as an RGB array (height, width, 3): the close-up of
    :func:`field_plotter` with, when ``inset``, an overview of the whole antenna pasted in the
    lower-left corner (30 % of each side), rendered by the same window without its text."""
    pl = field_plotter(ds, quantity, size)
    image = np.array(backend.screenshot(pl, None))
    if inset:
        for name in ("title", "notes", "labels", "bar_title", "axes"):
            pl.remove_actor(name, render=False)
        pl.remove_scalar_bar(render=False)
        w, h = inset_size(size)
        pl.window_size = [w, h]
        _overview_camera(pl, float(ds.attrs["diameter"]), float(ds.attrs["focal_length"]))
        picture = np.array(backend.screenshot(pl, None))[:h, :w]
        picture[[0, -1], :] = 60
        picture[:, [0, -1]] = 60
        margin = round(MARGIN * unit(size))
        bottom = size[1] - margin
        image[bottom - h:bottom, margin:margin + w] = picture
    pl.close()
    return image


MARGIN = 12.0  # px at the reference size, scaled by unit()
REFERENCE = (1600, 1200)  # the picture the text sizes (px) are chosen for


def unit(size: tuple[int, int]) -> float:
    """Scale of text and margins: the largest 4:3 box inside the picture over the reference
    1600 x 1200 (the scene fills that box, so text keeps its size relative to the scene)."""
    w, h = size
    return min(w / REFERENCE[0], h / REFERENCE[1])


def text_unit(size: tuple[int, int]) -> float:
    """Scale of text sizes: the picture's area over the reference's, square-rooted, at most 1.6
    :func:`unit` (a tall picture has room for larger text than its width alone gives)."""
    w, h = size
    return min(math.sqrt(w * h / (REFERENCE[0] * REFERENCE[1])), 1.6 * unit(size))


def inset_size(size: tuple[int, int]) -> tuple[int, int]:
    """The overview inset (width, height) px: 4:3, 30 % of the 4:3 box's width."""
    u = unit(size)
    return int(0.3 * REFERENCE[0] * u), int(0.3 * REFERENCE[1] * u)


def vtk_text(text: str) -> str:
    """``text`` in a notation VTK's text renders (it drops the | of |E|)."""
    return text.replace("|E|² / |E_inc|²", "I / I_inc").replace("|E|²/|E_inc|²", "I / I_inc")


def pixel_text(pl: Any, text: str, xy: tuple[float, float], size: float, name: str, halign: str,
               valign: str, max_width: float, color: str = "black") -> Any:
    """Text of ``size`` px with its (``halign``, ``valign``) corner at pixel ``xy`` (from the
    lower left), shrunk to ``max_width`` px if wider."""
    actor = pl.add_text(text, position=(float(xy[0]), float(xy[1])), font_size=max(7, round(size)) / 2,
                        color=color, name=name)  # pyvista doubles font_size for positioned text
    prop = actor.GetTextProperty()
    getattr(prop, f"SetJustificationTo{'Centered' if halign == 'center' else halign.capitalize()}")()
    getattr(prop, f"SetVerticalJustificationTo{'Centered' if valign == 'center' else valign.capitalize()}")()
    box = [0.0] * 4
    actor.GetBoundingBox(pl.renderer, box)
    width = box[1] - box[0]
    if width > max_width > 0:
        prop.SetFontSize(max(7, int(prop.GetFontSize() * max_width / width)))
    return actor


def what_of(q: Quantity) -> str:
    """The quantity's name for a title."""
    return {"fa": "Intensity ratio FA", "intensity": "Intensity",
            "normalized": "Intensity over the ideal GO law"}[q.name]


def _add_hemisphere(pl: Any, ds: xr.Dataset, q: Quantity, size: tuple[int, int], bar: bool = True) -> None:
    mesh = hemisphere(ds, q.values)
    w, h = size
    u, t = unit(size), text_unit(size)
    box_h = REFERENCE[1] * u
    # the colour bar at the right edge, its labels right of it, its title (a text of its own:
    # VTK centres a bar's title on the bar, cut at the picture's edge) above it
    right = w - MARGIN * u
    left = right - 45 * u - 125 * t
    bottom, top = h / 2 - 0.25 * box_h, h / 2 + 0.3 * box_h
    args = {"title": "colour", "vertical": True, "position_x": left / w, "position_y": bottom / h,
            "height": (top - bottom) / h, "width": (right - left) / w, "label_font_size": round(19 * t),
            "color": "black", "n_labels": 5, "fmt": _fmt(q.clim), "unconstrained_font_size": True}
    # data surfaces unlit, so the colour on the picture is the colour on the bar; only the inner
    # face (towards the focus) is drawn, as the probe sees it
    pl.add_mesh(mesh, scalars="value", cmap=q.cmap, clim=list(q.clim), nan_color=NAN_COLOR,
                lighting=False, scalar_bar_args=args, name="hemisphere", show_scalar_bar=bar,
                culling="back")
    if bar:
        scalar_bar = pl.scalar_bars["colour"]
        scalar_bar.SetTitle("")
        scalar_bar.SetBarRatio(45 * u / (right - left))
        pixel_text(pl, vtk_text(q.short), (right, top + 20 * t), 21 * t, "bar_title", "right", "bottom",
                   0.45 * w)
    pv = backend.pyvista()
    grid = grid_of(ds)
    # the open edge of the hemisphere (theta = 90 deg) as a thin circle for the shape
    edge = pv.Circle(radius=grid.radius * math.sin(grid.theta_max), resolution=180)
    edge = edge.extract_feature_edges(boundary_edges=True, feature_edges=False,
                                      manifold_edges=False, non_manifold_edges=False)
    edge.translate((0.0, 0.0, float(ds.attrs["focal_length"]) - grid.radius * math.cos(grid.theta_max)),
                   inplace=True)
    pl.add_mesh(edge, color="#303030", line_width=max(1.0, 2.0 * unit(size)), name="hemisphere_edge")
    if bar:  # the azimuth's axes where the edge crosses them (phi = 0 and 90 deg), as on the dish
        rim = 1.08 * grid.radius * math.sin(grid.theta_max)
        z = float(ds.attrs["focal_length"]) - grid.radius * math.cos(grid.theta_max)
        pl.add_point_labels(np.array([[rim, 0.0, z], [0.0, rim, z]]), ["+x (phi 0°)", "+y (phi 90°)"],
                            font_size=backend.points(19 * t), text_color="black", shape=None,
                            show_points=False, always_visible=True, name="axes")


def _add_focus_and_source(pl: Any, ds: xr.Dataset, F: float, R: float, D: float, u: float,
                          labels: bool = True) -> None:
    pv = backend.pyvista()
    focus = np.array([0.0, 0.0, F])
    pl.add_mesh(pv.Sphere(radius=0.04 * R, center=focus), color="black", name="focus")
    k_hat = source_direction(ds)
    length = 1.1 * R
    tails = []
    for k, offset in enumerate((-1.7 * R, 1.7 * R)):
        # two parallel rays of the plane wave either side of the hemisphere (one on the axis
        # would hide the data), tips level with a point above the focus
        tip = focus + np.array([offset, 0.0, 0.3 * R])
        tail = tip - k_hat * length
        tails.append(tail)
        pl.add_mesh(pv.Arrow(start=tail, direction=k_hat, scale=length, tip_length=0.25,
                             tip_radius=0.08, shaft_radius=0.03),
                    color="#c0392b", name=f"source_{k}")
    if not labels:
        return
    hz = float(ds.attrs.get("frequency_hz", float("nan")))
    points = np.array([focus + np.array([0.08 * R, 0.0, 0.08 * R]), tails[0] + np.array([0.0, 0.0, 0.1 * R])])
    pl.add_point_labels(points, ["focus", f"plane wave, {frequency_text(hz)}"],
                        font_size=backend.points(21 * u), text_color="black",
                        shape=None, show_points=False, always_visible=True, name="labels")


def _camera(pl: Any, centre: np.ndarray, distance: float, elevation_deg: float, azimuth_deg: float) -> None:
    """Look at ``centre`` (m) from ``distance`` (m) at an elevation and azimuth (deg), z up."""
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    direction = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    pl.camera.focal_point = tuple(centre)
    pl.camera.position = tuple(centre + direction * distance)
    pl.camera.up = (0.0, 0.0, 1.0)
    pl.camera.SetWindowCenter(0.0, 0.0)
    # 30 deg vertically in a 4:3 window; a narrower window keeps that width (the scene would
    # fill a portrait picture's width and run under the colour bar), a wider one that height
    w, h = pl.window_size
    if w / h < 4.0 / 3.0:
        pl.camera.SetUseHorizontalViewAngle(True)
        pl.camera.view_angle = math.degrees(2.0 * math.atan(math.tan(math.radians(15.0)) * 4.0 / 3.0))
    else:
        pl.camera.SetUseHorizontalViewAngle(False)
        pl.camera.view_angle = 30.0
    pl.camera.clipping_range = (0.02 * distance, 4.0 * distance)


def _overview_camera(pl: Any, D: float, F: float) -> None:
    """The whole antenna from the -y side, 24 deg above the aperture plane."""
    _camera(pl, np.array([0.0, 0.0, 0.45 * F]), 1.55 * D, 24.0, -70.0)


def _fmt(clim: tuple[float, float]) -> str:
    span = max(abs(clim[0]), abs(clim[1]))
    if span == 0 or span >= 1000 or span < 1e-2:
        return "%.2e"
    if span >= 10:
        return "%.1f"
    return "%.3f"
