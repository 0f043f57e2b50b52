"""The paper's figure set (Figs. 8a-d, 9, 10) for one run: a FieldMap and its SurfaceMap.

Frames and units (docs/physics.md): sphere angles in rad (shown in deg), aperture x, y in m, delta in
m (shown in µm). The aperture sees the sphere through the ideal GO mapping theta = 2 atan(r/2F),
phi = atan2(y, x) (paper Eq. 34); FA = I_ideal / I_def - 1 and G = -2 F d / R, d = F + z - R
(paper Eqs. 28-29). Figs. 8d and 9 show FA resampled onto the aperture grid by the solver's own
resampling (``solver.resample``: holes filled, rows up to the rim extrapolated, cubic spline),
so they show the data the inversion used (before its power-gain correction).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr
from scipy.interpolate import RegularGridInterpolator

from raysim.maps.aperture import ApertureGrid
from raysim.render import backend, charts
from raysim.render.backend import RenderError
from raysim.render.data import Quantity, fa, field_title, symmetric_limit
from solver.equation import G

Delta = Callable[[np.ndarray, np.ndarray], np.ndarray]
SIZE = (1400, 1050)


def laplacian(delta: Delta, x: np.ndarray, y: np.ndarray, h: float = 1e-2) -> np.ndarray:
    """Laplacian of delta(x, y) (1/m) by central differences of step ``h`` (m)."""
    return (delta(x + h, y) + delta(x - h, y) + delta(x, y + h) + delta(x, y - h)
            - 4.0 * delta(x, y)) / (h * h)


@dataclass(frozen=True)
class SceneTruth:
    """The scene's deformation delta(x, y, panel) (m) and its panel layout (None: one piece)."""

    deformation: Callable[..., np.ndarray]
    layout: Any = None

    def __call__(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """delta (m) at (x, y) (m)."""
        return self.deformation(x, y)

    def laplacian(self, x: np.ndarray, y: np.ndarray, h: float = 1e-2) -> np.ndarray:
        """Laplacian of delta (1/m) within the panel holding each point: the stencil (step h, m)
        evaluates that panel's surface, so panel edges and gaps add nothing (0 in a gap)."""
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        panel = self.layout.panel_at(x, y) if self.layout is not None else None
        return laplacian(lambda u, v: self.deformation(u, v, panel), x, y, h)


def scene_deformation(field: xr.Dataset) -> SceneTruth | None:
    """The true deformation of the scene the FieldMap carries, or None (measured scan, or a
    scene that refers to files not present here). A mesh scene's is its mesh's departure from
    its ideal with the scene's deformation on top (:func:`solver.invert.mesh_truth`; the
    scene's own deformation alone drew a flat zero for a mesh that departs)."""
    from raysim.scene.scene import scene_of
    from solver.invert import mesh_truth

    scene = scene_of(field)
    if scene is None:
        return None
    if scene.dish.mesh is None:
        return SceneTruth(scene.deformation, scene.panels)
    delta = mesh_truth(scene, dict(field.attrs))
    return None if delta is None else SceneTruth(lambda x, y, panel=None: delta(x, y))


def fa_on_aperture(field: xr.Dataset, x: np.ndarray) -> np.ndarray:
    """FA of the FieldMap resampled by the solver onto the aperture grid with cell centres ``x``
    (= y, m, N of them spanning D), indexed [y, x]; NaN outside the aperture."""
    from raysim.maps.fieldmap import grid_of
    from solver.resample import sphere_to_aperture

    D, F = float(field.attrs["diameter"]), float(field.attrs["focal_length"])
    grid = ApertureGrid(D, len(x))
    if not np.allclose(grid.x, x, atol=1e-9 * D):
        raise RenderError("the aperture grid must be N cell centres spanning D")
    values, _ = sphere_to_aperture(fa(field), grid_of(field), grid, F, D)
    return values


def truth_laplacian(truth: SceneTruth | None, surface: xr.Dataset | None) -> Delta | None:
    """Laplacian of the true delta (1/m) at any points: from the scene's delta (central
    differences within each panel), else from the SurfaceMap's ``truth`` grid (5-point,
    bilinear between points)."""
    if truth is not None:
        return truth.laplacian
    if surface is None or "truth" not in surface.data_vars:
        return None
    values = surface["truth"].values
    h = float(surface["x"].values[1] - surface["x"].values[0])
    lap = np.full(values.shape, np.nan)
    lap[1:-1, 1:-1] = (values[2:, 1:-1] + values[:-2, 1:-1] + values[1:-1, 2:] + values[1:-1, :-2]
                       - 4 * values[1:-1, 1:-1]) / (h * h)
    interp = RegularGridInterpolator((surface["y"].values, surface["x"].values), lap, bounds_error=False,
                                     fill_value=np.nan)
    return lambda x, y: interp(np.stack([np.ravel(y), np.ravel(x)], axis=-1)).reshape(np.shape(x))


# --- the figures -----------------------------------------------------------------------------
def fig8a_deformation(truth: xr.Dataset, size: tuple[int, int] = SIZE) -> np.ndarray:
    """Fig. 8a: the assumed deformation as a warped dish (a SurfaceMap-like dataset whose
    ``deformation`` is the truth), RGB image."""
    from raysim.render.surface3d import surface_plotter

    pl = surface_plotter(truth, size, title="Assumed deformation delta (scene)")
    image = np.array(backend.screenshot(pl, None))
    pl.close()
    return image


def fig8b_ideal_amplitude(field: xr.Dataset, size: tuple[int, int] = SIZE):
    """Fig. 8b: amplitude |E| / |E_inc| of the ideal reflector on the sphere."""
    amplitude = np.sqrt(np.clip(field["intensity_ideal"].values.astype(np.float64), 0.0, None))
    finite = amplitude[np.isfinite(amplitude)]
    q = Quantity("amplitude", amplitude, "|E| / |E_inc| of the ideal reflector", "viridis",
                 (0.0, float(finite.max()) if finite.size else 1.0), False, "|E|/|E_inc|")
    return charts.field_map(field, q, size, title="Ideal amplitude on the sphere (Fig. 8b)")


def fig8c_fa_sphere(field: xr.Dataset, size: tuple[int, int] = SIZE):
    """Fig. 8c: FA = I_ideal / I_def - 1 on the sphere, before resampling."""
    return charts.field_map(field, "fa", size, title="FA on the sphere, before resampling (Fig. 8c)")


def fig8d_fa_aperture(field: xr.Dataset, x: np.ndarray, size: tuple[int, int] = SIZE):
    """Fig. 8d: FA resampled onto the aperture grid x = y (m) through the ideal GO mapping."""
    values = fa_on_aperture(field, x)
    fig = backend.figure(size)
    fig.suptitle(field_title(field, "FA after resampling onto the aperture (Fig. 8d)")
                 + "\nideal GO mapping r = 2F tan(theta/2), the solver's resampling", fontsize=12)
    ax = fig.subplots()
    limit = symmetric_limit(values)
    image = ax.pcolormesh(charts.cell_edges(x), charts.cell_edges(x), np.ma.masked_invalid(values),
                          cmap=charts.colour_map("RdBu_r"), vmin=-limit, vmax=limit, shading="flat",
                          rasterized=True)
    charts.rim_circle(ax, 0.5 * float(field.attrs["diameter"]))
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    fig.colorbar(image, ax=ax, label="FA = I_ideal / I_def - 1", extend="both")
    return fig


def fig9_equation(field: xr.Dataset, x: np.ndarray, lap: Delta | None, size: tuple[int, int] = SIZE):
    """Fig. 9: FA (resampled onto the aperture grid x = y, m) against G Laplacian(delta) along
    the x axis (y = 0) and the y axis (x = 0)."""
    F, R = float(field.attrs["focal_length"]), float(field.attrs["sphere_radius"])
    values = fa_on_aperture(field, x)
    fig = backend.figure(size)
    fig.suptitle(field_title(field, "FA against G Laplacian(delta) along cuts (Fig. 9)")
                 + "\nG = -2 F d / R, d = F + z - R; FA resampled from the sphere", fontsize=12)
    axes = fig.subplots(2, 1, sharex=True)
    zero = np.zeros_like(x)
    cuts = (("x axis (y = 0)", x, zero, charts.profile_at_zero(values, x, axis=0)),
            ("y axis (x = 0)", zero, x, charts.profile_at_zero(values, x, axis=1)))
    for ax, (name, px, py, measured) in zip(axes, cuts, strict=True):
        ax.plot(x, measured, color="C0", label="FA from the intensities")
        curves = [measured]
        if lap is not None:
            curves.append(G(np.hypot(px, py), F, R) * lap(px, py))
            ax.plot(x, curves[-1], color="C3", linestyle="--", label="G Laplacian(delta), true delta")
        # a few spikes (gap images, the pole) must not flatten the rest: clip at 1.3 x the 99th
        # percentile and say so
        limit = 1.3 * symmetric_limit(np.concatenate(curves), 99.0)
        if np.nanmax(np.abs(np.concatenate(curves))) > limit:
            ax.set_ylim(-limit, limit)
            ax.text(0.01, 0.97, "some values off scale", transform=ax.transAxes, va="top", fontsize=9,
                    color="0.3")
        ax.set_title(f"along the {name}", fontsize=11)
        ax.set_ylabel("FA (dimensionless)")
        ax.grid(True, alpha=0.3)
    # one legend for both cuts, below them: inside an axes it would hide a stretch of the curves
    fig.legend(handles=axes[0].get_lines(), loc="outside lower center", ncol=2, fontsize=10,
               frameon=False)
    axes[-1].set_xlabel("position along the cut (m)")
    return fig


def fig10_recovered(surface: xr.Dataset, size: tuple[int, int] = SIZE):
    """Fig. 10: recovered against true deformation along cuts (µm)."""
    return charts.surface_cut(surface, size)


def aperture_x(field: xr.Dataset, surface: xr.Dataset | None, N: int = 256) -> np.ndarray:
    """Aperture grid coordinates (m): the SurfaceMap's x, else N cell centres across D."""
    if surface is not None:
        return surface["x"].values
    return ApertureGrid(float(field.attrs["diameter"]), N).x


def truth_dataset(field: xr.Dataset, surface: xr.Dataset | None, truth: Delta | None) -> xr.Dataset | None:
    """A SurfaceMap-like dataset holding the true delta as ``deformation`` (for Fig. 8a): the
    SurfaceMap's ``truth`` when present, else the scene's delta on :func:`aperture_x`'s grid,
    NaN outside the aperture; None when neither exists."""
    x = aperture_x(field, surface)
    if surface is not None and "truth" in surface.data_vars:
        values = surface["truth"].values
    elif truth is not None:
        grid = ApertureGrid(float(field.attrs["diameter"]), len(x))
        values = grid.masked(truth(*grid.XY))
    else:
        return None
    attrs = {k: field.attrs[k] for k in ("focal_length", "diameter", "sphere_radius")}
    coords = {"x": ("x", x, {"units": "m"}), "y": ("y", x, {"units": "m"})}
    return xr.Dataset({"deformation": (("y", "x"), values, {"units": "m"})}, coords=coords, attrs=attrs)
