"""FieldMap pictures rendered headless: sizes, colour ranges, and features at the right pixels.

The maps come from the linear deformation-intensity equation (tests/examples.py), so the
tests need neither the ray engine nor a display. The "gap ring" is what a 10 mm panel gap
leaves in a GO map of 1-degree cells: one row of cells about 1.5 % darker, at the theta where
the ideal mapping r = 2F tan(theta/2) sends the gap's radius.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from raysim.maps.sphere import theta_of_radius
from raysim.render import backend, charts, render_image
from raysim.render.data import fa, field_quantity
from raysim.render.field3d import field_plotter
from raysim.surface.deformation import NoDeformation, PaperDeformation
from tests.examples import equation_fieldmap

D, F, R = 110.0, 33.0, 10.0
SIZE = (1200, 900)
RING_EDGES = (13.75, 27.5, 41.25)  # m: panel ring edges of scenes/panels_go.toml


def gap_rows(ds) -> list[int]:
    """theta rows holding the images of the ring edges."""
    edges = np.degrees(ds["theta"].values[0]) - 0.5
    return [int(np.degrees(theta_of_radius(r, F)) - edges) for r in RING_EDGES]


@pytest.fixture(scope="module")
def flat_field():
    return equation_fieldmap(NoDeformation(), D, F, R)


@pytest.fixture(scope="module")
def gapped_field(flat_field):
    ds = flat_field.copy(deep=True)
    for row in gap_rows(ds):
        ds["intensity"].values[row, :] *= 0.985
    return ds


@pytest.fixture(scope="module")
def paper_field():
    return equation_fieldmap(PaperDeformation(D, F), D, F, R)


def luminance(image: np.ndarray) -> np.ndarray:
    return image[..., :3].astype(np.float64) @ np.array([0.299, 0.587, 0.114])


def near_colour(image: np.ndarray, rgb, tol: float = 40.0) -> int:
    """Number of pixels within ``tol`` (0-255 units, Euclidean) of the colour ``rgb``."""
    target = np.asarray(rgb, dtype=np.float64)[:3] * 255.0
    return int(np.count_nonzero(np.linalg.norm(image[..., :3] - target, axis=-1) < tol))


def test_3d_picture_has_the_size_asked_and_spans_the_data(paper_field):
    import matplotlib

    image = render_image(paper_field, "3d", SIZE, "fa")
    assert image.shape == (SIZE[1], SIZE[0], 3)
    q = field_quantity(paper_field, "fa")
    assert q.clim[0] == -q.clim[1]  # diverging map centred on 0
    cmap = matplotlib.colormaps[q.cmap]
    lowest, highest = np.nanmin(q.values), np.nanmax(q.values)
    # the colours of the data's minimum and maximum both cover many cells' worth of pixels
    # (far more than the colour bar's strip), and white (FA = 0) lies between them
    for value in (lowest, highest):
        assert near_colour(image, cmap(0.5 + 0.5 * value / q.clim[1]), tol=25) > 1500
    assert near_colour(image, cmap(0.5), tol=25) > 1500
    assert backend.colour_count(image) > 2000


def test_3d_picture_says_what_its_colour_scale_clips_and_marks_the_axes(paper_field):
    """The bar ends at a percentile: FA of a bump reached 1.97e-2 under a bar of 2.61e-3 and
    nothing said so; nor did anything tell the hemisphere's azimuth."""
    from raysim.render.field3d import clipping_note

    q = field_quantity(paper_field, "fa")
    values = q.values[np.isfinite(q.values)]
    beyond = np.count_nonzero(np.abs(values) > q.clim[1])
    (line,) = clipping_note(q)
    assert line.startswith(f"{100 * beyond / values.size:.2g} % of the cells beyond")
    low, high = (float(v) for v in line.split("(values ")[1].rstrip(")").split(" to "))
    np.testing.assert_allclose([low, high], [values.min(), values.max()], rtol=0.05)
    inside = replace(q, clim=(1.01 * values.min(), 1.01 * values.max()))
    assert clipping_note(inside) == []
    pl = field_plotter(paper_field, "fa", SIZE)
    assert "axes-labels" in pl.actors
    pl.close()


def ring_contrast(ds, quantity: str = "normalized", rows: list[int] | None = None) -> np.ndarray:
    """Luminance of the gap rows' pixels minus that of the rows 3 cells either side, along phi,
    where the camera sees the hemisphere's inner face (the outer face is not drawn)."""
    pl = field_plotter(ds, quantity, SIZE)
    image = luminance(backend.screenshot(pl, None))
    camera = np.array(pl.camera.position)
    focus = np.array([0.0, 0.0, F])
    grid_theta = ds["theta"].values
    out = []
    for row in rows or gap_rows(ds):
        for phi in np.radians(np.arange(5.0, 360.0, 10.0)):
            def point(t, phi=phi):
                return np.array([R * np.sin(t) * np.cos(phi), R * np.sin(t) * np.sin(phi), F - R * np.cos(t)])

            def pixel(t):
                c, r = backend.project(pl, point(t))[0]
                r, c = round(r), round(c)
                return image[r - 1:r + 2, c - 1:c + 2].min()

            p = point(grid_theta[row])
            if np.dot(focus - p, camera - p) <= 0:
                continue  # seen from behind: culled, the picture shows what lies beyond
            on = pixel(grid_theta[row])
            off = 0.5 * (pixel(grid_theta[row - 3]) + pixel(grid_theta[row + 3]))
            out.append(on - off)
    pl.close()
    assert len(out) > 0.5 * len(rows or gap_rows(ds)) * 36  # most of each ring is in view
    return np.array(out)


def test_gap_rings_land_where_the_ideal_mapping_sends_the_ring_edges(gapped_field, flat_field):
    contrast = ring_contrast(gapped_field)
    # dark pixels where the ring-edge rows project, all round the hemisphere
    assert np.mean(contrast < -25.0) > 0.9, np.round(contrast).tolist()
    # the same probe on the map without gaps finds nothing there
    control = ring_contrast(flat_field)
    assert np.mean(np.abs(control) < 10.0) > 0.9, np.round(control).tolist()


@pytest.mark.slow
def test_gap_rings_of_a_traced_panel_dish_land_at_its_ring_edges():
    """The panels scene traced with GO (coarser mesh, no panel errors): the gap images the
    engine puts on the sphere show as dark rings where the ring edges project."""
    import dataclasses

    from raysim.scene.scene import load_scene
    from raysim.simulate import simulate
    from raysim.surface.deformation import NoDeformation

    scene = load_scene(Path(__file__).resolve().parents[3] / "scenes" / "panels_go.toml")
    scene = dataclasses.replace(scene, dish=dataclasses.replace(scene.dish, resolution=0.3),
                                deformation=NoDeformation())
    ds = simulate(scene)
    edges = scene.panels.ring_edges[1:-1]
    rows = [int(np.degrees(theta_of_radius(r, F))) for r in edges]  # 1-degree rows from theta = 0
    contrast = ring_contrast(ds, rows=rows)
    assert np.median(contrast) < -25.0 and np.mean(contrast < -10.0) > 0.85, np.round(contrast).tolist()


def test_2d_map_puts_the_gap_ring_at_its_theta_in_both_panels(gapped_field):
    fig = charts.field_map(gapped_field, "normalized", SIZE)
    image = luminance(backend.figure_image(fig))
    assert image.shape == (SIZE[1], SIZE[0])
    plan, rect = fig.axes[0], fig.axes[1]
    height = SIZE[1]
    theta = np.degrees(gapped_field["theta"].values)
    for row in gap_rows(gapped_field):
        for phi_deg in (45.0, 135.0, 225.0, 315.0):
            def value(ax, t, phi_deg=phi_deg):
                xy = (phi_deg, t) if ax is rect else (t * np.cos(np.radians(phi_deg)),
                                                        t * np.sin(np.radians(phi_deg)))
                x, y = ax.transData.transform(xy)
                row, col = round(height - y), round(x)
                return image[row - 1:row + 2, col - 1:col + 2].min()
            for ax in (rect, plan):
                assert value(ax, theta[row]) < min(value(ax, theta[row - 3]), value(ax, theta[row + 3])) - 25


def test_cut_draws_the_fa_of_each_cut_where_the_data_are(paper_field):
    import matplotlib

    fig = charts.field_cut(paper_field, SIZE)
    image = backend.figure_image(fig).astype(np.float64)
    assert image.shape == (SIZE[1], SIZE[0], 3)
    top, bottom = fig.axes[0], fig.axes[1]
    ratio = fa(paper_field)
    theta = np.degrees(paper_field["theta"].values)
    last = bottom.lines[3]  # the cut drawn last (phi = 270 deg) is on top where cuts overlap
    j = int(np.argmin(np.abs(np.degrees(paper_field["phi"].values) - 270.0)))
    np.testing.assert_allclose(last.get_ydata(), ratio[:, j])
    colour = np.array(matplotlib.colors.to_rgb(last.get_color())) * 255
    hits = 0
    lit = np.flatnonzero(np.isfinite(ratio[:, j]))[::7]
    for i in lit:
        x, y = bottom.transData.transform((theta[i], ratio[i, j]))
        row, col = round(SIZE[1] - y), round(x)
        patch = image[row - 2:row + 3, col - 2:col + 3].reshape(-1, 3)
        hits += np.min(np.linalg.norm(patch - colour, axis=1)) < 30
    assert hits == len(lit)
    # the intensity panel holds the deformed and the ideal curve of each cut
    assert len(top.lines) >= 8
    assert max(np.nanmax(line.get_ydata()) for line in top.lines if len(line.get_ydata())) > 25


def test_cut_draws_the_rim_image_its_label_promises(paper_field):
    """The label said "dashed: rim image" and no line was drawn."""
    D, F = (float(paper_field.attrs[k]) for k in ("diameter", "focal_length"))
    rim = np.degrees(2.0 * np.arctan(D / (4.0 * F)))                 # the ideal GO rim ray
    fig = charts.field_cut(paper_field, SIZE)
    for ax in fig.axes[:2]:
        dashed = [line for line in ax.lines if line.get_linestyle() == "--"]
        assert len(dashed) == 1
        np.testing.assert_allclose(dashed[0].get_xdata(), [rim, rim])
    assert fig.axes[1].get_xlabel().endswith("dashed: rim image")
    short = paper_field.isel(theta=slice(0, 40))                      # stops at 40 deg
    short.attrs.pop("theta_max", None)                 # its edges from its own rows
    fig = charts.field_cut(short, SIZE)
    assert not [line for line in fig.axes[1].lines if line.get_linestyle() == "--"]
    assert f"rim image at {rim:.2f}°, beyond the scan" in fig.axes[1].get_xlabel()


def test_measured_scan_without_scene_draws_the_ideal_dish_and_grey_holes(paper_field):
    """A measured scan has no scene and may miss samples: the dish comes from the attributes,
    missing cells show in the no-value grey, every kind renders."""
    from raysim.render.field3d import NAN_COLOR, reflector

    complete = paper_field.copy(deep=True)
    complete.attrs["method"] = "measured"
    complete.attrs.pop("scene", None)
    ds = complete.copy(deep=True)
    ds["intensity"].values[20:30, 40:80] = np.nan  # a block of failed readings, facing the camera
    _, _, what = reflector(ds)
    assert what.startswith("ideal paraboloid")
    grey = tuple(int(NAN_COLOR[k:k + 2], 16) / 255 for k in (1, 3, 5))
    # the band beyond the rim image is grey in both; the holes add their own grey pixels
    before = near_colour(render_image(complete, "3d", SIZE, "fa"), grey, tol=6)
    image = render_image(ds, "3d", SIZE, "fa")
    assert near_colour(image, grey, tol=6) > before + 300
    for kind in ("map", "cut"):
        assert render_image(ds, kind, SIZE).shape == (SIZE[1], SIZE[0], 3)
