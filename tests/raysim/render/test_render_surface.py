"""SurfaceMap pictures rendered headless: a single Gaussian bump must peak at the pixel where
its top projects (3D warped dish) or where its centre lies (2D map); truth / recovered / error
pictures carry three panels with their own statistics."""

from __future__ import annotations

import numpy as np
import pytest

from raysim.render import backend, charts, render_image
from raysim.render.data import error_summary, rms, surface_panels
from raysim.render.surface3d import exaggeration, surface_plotter
from raysim.surface.deformation import GaussianBumps, PaperDeformation
from tests.examples import surfacemap

D, F = 110.0, 33.0
SIZE = (1200, 900)
AMPLITUDE, SIGMA = 300e-6, 4.0


def bump_map(x0: float, y0: float):
    return surfacemap(GaussianBumps(((x0, y0, AMPLITUDE, SIGMA),)), D, N=128, F=F)


def redness(image: np.ndarray) -> np.ndarray:
    """How far a pixel is towards the deep red end of RdBu_r (red minus the larger of G, B)."""
    rgb = image[..., :3].astype(np.float64)
    return rgb[..., 0] - np.maximum(rgb[..., 1], rgb[..., 2])


@pytest.mark.parametrize("x0, y0", [(15.0, -10.0), (-22.0, 20.0)])
def test_bump_top_lands_at_its_projected_pixel_on_the_warped_dish(x0, y0):
    ds = bump_map(x0, y0)
    pl = surface_plotter(ds, SIZE)
    image = backend.screenshot(pl, None)
    assert image.shape == (SIZE[1], SIZE[0], 3)
    k = exaggeration(ds["deformation"].values, D)
    top = np.array([x0, y0, (x0 * x0 + y0 * y0) / (4 * F) + k * AMPLITUDE])
    col, row = backend.project(pl, top, subplot=(1, 0))[0]
    pl.close()
    score = redness(image)
    score[int(0.85 * SIZE[1]):] = 0.0  # the colour bar strip at the bottom has the same red
    strong = score > 0.8 * score.max()
    rows, cols = np.nonzero(strong)
    assert score.max() > 80  # a deep red blob exists at all
    # the deepest red sits at the bump's top: within 2 % of the picture width
    distance = np.hypot(rows.mean() - row, cols.mean() - col)
    assert distance < 0.02 * SIZE[0], (rows.mean(), cols.mean(), row, col)


def test_bump_peak_lands_at_its_centre_on_the_2d_map():
    x0, y0 = 15.0, -10.0
    fig = charts.surface_map(bump_map(x0, y0), SIZE)
    image = backend.figure_image(fig)
    assert image.shape == (SIZE[1], SIZE[0], 3)
    ax = fig.axes[0]
    score = redness(image)
    # only inside the map's axes: the colour bar elsewhere has the same red
    (left, bottom), (right, top) = ax.transAxes.transform([(0, 0), (1, 1)])
    inside = np.zeros_like(score, dtype=bool)
    inside[int(SIZE[1] - top):int(SIZE[1] - bottom), int(left):int(right)] = True
    score[~inside] = 0
    rows, cols = np.nonzero(score > 0.95 * score.max())
    x, y = ax.transData.transform((x0, y0))
    assert np.hypot(rows.mean() - (SIZE[1] - y), cols.mean() - x) < 4.0
    # and the map is not one colour: the rest of the aperture is near white (delta ~ 0)
    assert np.count_nonzero((image[inside] > 240).all(axis=-1)) > 0.3 * inside.sum()


@pytest.fixture(scope="module")
def with_truth():
    truth = PaperDeformation(D, F)
    return surfacemap(lambda x, y: 0.95 * truth(x, y) + 2e-5 * np.cos(x / 7.0), D, N=128, truth=truth, F=F,
                      attrs={"solver": "example", "data_method": "go", "data_frequency_hz": 0.3e9})


def test_truth_recovered_error_side_by_side_in_3d(with_truth):
    image = render_image(with_truth, "3d")
    assert image.shape == (1000, 2400, 3)  # the default for three panels
    thirds = [image[150:850, k * 800:(k + 1) * 800] for k in range(3)]
    colours = [backend.colour_count(t) for t in thirds]
    assert min(colours) > 1000
    # truth and recovered share one colour scale and look alike; the error does not
    truth_red, recovered_red, error_red = (np.mean(redness(t) > 60) for t in thirds)
    assert abs(truth_red - recovered_red) < 0.3 * truth_red
    assert abs(error_red - truth_red) > 0.1 * truth_red


def test_maps_and_cuts_of_truth_recovered_error(with_truth):
    fig = charts.surface_map(with_truth, (2400, 1000))
    titles = [ax.get_title() for ax in fig.axes[:3]]
    assert [t.split(":")[0] for t in titles] == ["truth", "recovered", "error"]
    panels = dict(surface_panels(with_truth))
    assert f"{rms(panels['error']) * 1e6:.4g} µm" in titles[2]
    cut = charts.surface_cut(with_truth, SIZE)
    image = backend.figure_image(cut)
    assert image.shape == (SIZE[1], SIZE[0], 3)
    ax = cut.axes[0]
    x = with_truth["x"].values
    truth_line = next(line for line in ax.lines if line.get_label() == "truth")
    # y = 0 lies between two grid rows: the cut interpolates them
    j = np.searchsorted(with_truth["y"].values, 0.0)
    expected = 0.5 * (panels["truth"][j - 1] + panels["truth"][j]) * 1e6
    np.testing.assert_allclose(truth_line.get_xdata(), x)
    np.testing.assert_allclose(truth_line.get_ydata(), expected)


def test_error_summary_is_rms_over_the_aperture_and_rrms_over_peak_to_peak(with_truth):
    error = with_truth["error"].values
    truth = with_truth["truth"].values
    inside = np.isfinite(truth)
    expected_rms = np.sqrt(np.mean(error[inside] ** 2))
    expected_rrms = expected_rms / (truth[inside].max() - truth[inside].min())
    text = error_summary(with_truth)
    assert f"RMS error {expected_rms * 1e6:.3g} µm" in text
    assert f"RRMS {100 * expected_rrms:.3g} %" in text


def test_exaggeration_is_a_round_factor_giving_about_six_percent_of_d():
    values = np.array([-600e-6, 612e-6])
    k = exaggeration(values, 110.0)
    assert k == 5000.0
    assert 0.03 * 110 < k * 1212e-6 <= 0.06 * 110


def test_text_scale_enlarges_the_text_not_the_picture(with_truth):
    """A wide picture shown shrunk keeps legible labels: text_scale draws them larger on the same
    pixels."""
    heights = {}
    for scale in (1.0, 1.7):
        fig = charts.surface_map(with_truth, (2400, 1000), text_scale=scale)
        image = backend.figure_image(fig)
        assert image.shape == (1000, 2400, 3)
        renderer = fig.canvas.get_renderer()
        heights[scale] = np.median([t.get_window_extent(renderer).height
                                    for t in fig.axes[0].get_xticklabels() if t.get_text()])
    assert heights[1.7] == pytest.approx(1.7 * heights[1.0], rel=0.1)
    with pytest.raises(backend.RenderError):
        backend.figure((2400, 1000), text_scale=0.0)


@pytest.mark.parametrize("size", [(1400, 600), (2400, 600), (1600, 1200)])
def test_a_map_without_truth_is_one_panel_centred_in_the_picture(size):
    """A measured SurfaceMap (no truth, no error): one image panel holding the map, and the
    picture's content centred (the one panel was pushed to the right edge of a wide picture,
    its left two-thirds blank)."""
    ds = bump_map(15.0, -10.0)
    assert "truth" not in ds and "error" not in ds
    fig = charts.surface_map(ds, size)
    image = backend.figure_image(fig)
    maps = [ax for ax in fig.axes if ax.collections and ax.get_label() != "<colorbar>"]
    assert len(maps) == len(surface_panels(ds)) == 1
    assert np.isfinite(maps[0].collections[0].get_array()).sum() > 1000  # not an empty panel
    # below the titles, the columns that hold anything but white: as much blank either side
    body = image[int(0.15 * size[1]):]
    columns = np.nonzero((body < 230).any(axis=-1).any(axis=0))[0]
    left, right = columns[0], size[0] - 1 - columns[-1]
    assert abs(left - right) < 0.04 * size[0], (left, right)


def test_truth_recovered_error_fill_three_image_panels(with_truth):
    fig = charts.surface_map(with_truth, (2400, 1000))
    maps = [ax for ax in fig.axes if ax.collections and ax.get_label() != "<colorbar>"]
    assert len(maps) == 3
    for ax in maps:
        assert np.isfinite(np.ma.filled(ax.collections[0].get_array(), np.nan)).sum() > 1000
