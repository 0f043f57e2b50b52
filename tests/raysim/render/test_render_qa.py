"""Pictures of degenerate maps and odd sizes: a flat SurfaceMap, measured scans, maps with no
finite value, one-row maps, output names naming folders, options that do not apply, and text
that must stay inside the picture and clear of other text at aspect ratios from 1:2 to 2:1."""

from __future__ import annotations

import numpy as np
import pytest

from raysim.maps.fieldmap import save
from raysim.render import RenderError, backend, charts, render
from raysim.render.data import error_summary, field_subtitle, field_title
from raysim.surface.deformation import NoDeformation, PaperDeformation
from tests.cli import run_in_process
from tests.examples import equation_fieldmap, surfacemap


def zero(x, y):
    return 0.0 * x


@pytest.fixture(scope="module")
def flat_surface():
    return surfacemap(zero, N=64, truth=zero, F=33.0)


def test_a_flat_surface_map_is_drawn_on_a_one_micrometre_scale_without_nan(flat_surface):
    for kind in ("map", "cut"):
        fig = (charts.surface_map if kind == "map" else charts.surface_cut)(flat_surface, (1600, 1200))
        assert "nan" not in fig.get_suptitle().lower()
    fig = charts.surface_map(flat_surface, (2400, 1000))
    for ax in fig.axes[:3]:
        assert ax.collections[0].get_clim() == (-1.0, 1.0)  # µm, not ±1 m
    text = error_summary(flat_surface)
    assert "RMS error 0 µm" in text and "flat" in text and "nan" not in text.lower()


def test_a_measured_scan_says_measured_once_and_gives_both_cell_steps():
    ds = equation_fieldmap(NoDeformation(), n_theta=9, n_phi=12, scene_name="")
    ds.attrs["method"] = "measured"
    ds.attrs.pop("scene_name", None)
    title = field_title(ds, "FA")
    assert title.count("measured") == 1, title
    assert title == "FA — measured scan, 0.30 GHz"
    # 90 deg / 9 rows = 10 deg in theta, 360 deg / 12 columns = 30 deg in phi
    assert "(10° in theta x 30° in phi)" in field_subtitle(ds)
    assert "(1°)" in field_subtitle(equation_fieldmap(NoDeformation()))


def test_a_one_row_map_states_its_steps_and_its_cut_lists_each_curve_once():
    ds = equation_fieldmap(PaperDeformation(110.0, 33.0), n_theta=1, n_phi=4)
    assert "nan" not in field_subtitle(ds)
    assert "(90°)" in field_subtitle(ds)  # one row over 0..90 deg, four columns of 90 deg
    fig = charts.field_cut(ds, (1600, 1200))
    bottom = fig.axes[1]
    labels = bottom.get_legend_handles_labels()[1]
    assert len(labels) == len(set(labels)) == 3  # cells at 45, 135, 225 deg nearest 0..270
    # each drawn curve is visible as a marker: one theta row is one point
    curves = [line for line in bottom.lines if line.get_linestyle() != "--"]  # not the rim's
    assert len(curves) == 3 and all(line.get_marker() not in (None, "None", "") for line in curves)


def test_a_cut_lists_only_the_curves_it_draws():
    ds = equation_fieldmap(PaperDeformation(110.0, 33.0), n_theta=45, n_phi=180)
    j = int(np.argmin(np.abs(ds["phi"].values - np.radians(90.0))))
    ds["intensity"].values[:, j] = np.nan
    fig = charts.field_cut(ds, (1600, 1200))
    top, bottom = fig.axes[:2]
    for ax in (top, bottom):
        labels = ax.get_legend_handles_labels()[1]
        assert not any("phi = 89" in s or "phi = 91" in s for s in labels), labels
        assert sum("phi =" in s for s in labels) == 3


@pytest.fixture(scope="module")
def empty_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("empty")
    field = equation_fieldmap(NoDeformation(), n_theta=30, n_phi=60)
    field["intensity"].values[:] = np.nan
    surface = surfacemap(zero, N=32, truth=zero, F=33.0)
    surface["truth"].values[:] = np.nan
    surface_path = folder / "surface.nc"
    surface.to_netcdf(surface_path)
    return save(field, folder / "field.nc"), surface_path


@pytest.mark.parametrize("which, kind", [(0, "3d"), (0, "map"), (0, "cut"), (1, "map")])
def test_maps_with_no_finite_value_are_refused_and_leave_the_output_alone(capsys, empty_files, tmp_path,
                                                                          which, kind):
    out = tmp_path / "picture.png"
    out.write_bytes(b"earlier picture")
    code, _, err = run_in_process(capsys, "render", str(empty_files[which]), "-o", str(out), "--kind", kind)
    assert code == 2
    assert "no finite value" in err and len(err.strip().splitlines()) == 1
    assert out.read_bytes() == b"earlier picture"


def test_an_output_name_ending_in_a_slash_is_refused(capsys, tmp_path):
    field = save(equation_fieldmap(NoDeformation(), n_theta=30, n_phi=60), tmp_path / "field.nc")
    code, _, err = run_in_process(capsys, "render", str(field), "-o", f"{tmp_path / 'x.png'}/", "--kind", "map")
    assert code == 2 and "folder" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.png").exists()
    with pytest.raises(RenderError, match="folder"):
        render(field, f"{tmp_path / 'y.png'}/", kind="map")
    assert not (tmp_path / "y.png").exists()


def test_quantity_is_refused_for_a_surface_map_only_when_given(capsys, tmp_path):
    path = tmp_path / "surface.nc"
    surfacemap(PaperDeformation(110.0, 33.0), N=32, F=33.0).to_netcdf(path)
    out = tmp_path / "s.png"
    code, _, err = run_in_process(capsys, "render", str(path), "-o", str(out), "--quantity", "fa")
    assert code == 2 and "--quantity" in err and "SurfaceMap" in err
    assert len(err.strip().splitlines()) == 1 and not out.exists()
    code, _, err = run_in_process(capsys, "render", str(path), "-o", str(out), "--size", "800x600")
    assert code == 0, err
    assert out.exists()


def test_sizes_too_small_to_read_are_refused(capsys, tmp_path):
    field = save(equation_fieldmap(NoDeformation(), n_theta=30, n_phi=60), tmp_path / "field.nc")
    code, _, err = run_in_process(capsys, "render", str(field), "-o", str(tmp_path / "x.png"), "--kind", "map",
                                  "--size", "200x150")
    assert code == 2 and "outside" in err and len(err.strip().splitlines()) == 1


# --- layout ----------------------------------------------------------------------------------
SIZES = [(800, 1600), (800, 600), (1600, 1200), (1600, 800), (2400, 1000)]


def overlap(a, b) -> bool:
    """Whether two boxes (x0, y0, x1, y1) share area (a pixel of slack)."""
    return min(a[2], b[2]) - max(a[0], b[0]) > 1 and min(a[3], b[3]) - max(a[1], b[1]) > 1


def drawn_box(fig) -> tuple[float, float, float, float]:
    """Pixel box (x0, y0, x1, y1) of everything a figure draws (text included)."""
    backend.figure_image(fig)
    box = fig.get_tightbbox(fig.canvas.get_renderer())
    return tuple(v * fig.dpi for v in box.extents)


@pytest.fixture(scope="module")
def with_truth():
    truth = PaperDeformation(110.0, 33.0)
    return surfacemap(lambda x, y: 0.95 * truth(x, y), N=64, truth=truth, F=33.0,
                      attrs={"solver": "multigrid", "data_method": "go", "data_frequency_hz": 0.3e9,
                             "boundary": "zero on the rim (the paper's assumption)"})


@pytest.mark.parametrize("size", SIZES)
def test_chart_text_stays_inside_the_picture_and_titles_do_not_overlap(with_truth, size):
    field = equation_fieldmap(PaperDeformation(110.0, 33.0), n_theta=45, n_phi=90)
    figures = [charts.surface_map(with_truth, size), charts.surface_cut(with_truth, size)]
    if size[0] <= 2 * size[1]:  # 1:2 to 2:1 (2400 x 1000 is the three panels' default only)
        figures += [charts.field_map(field, "fa", size), charts.field_cut(field, size)]
    for fig in figures:
        x0, y0, x1, y1 = drawn_box(fig)
        assert x0 >= -1 and y0 >= -1 and x1 <= size[0] + 1 and y1 <= size[1] + 1, (size, fig.get_suptitle())
        titles = [fig._suptitle.get_window_extent()] + [ax.title.get_window_extent()
                                                         for ax in fig.axes if ax.get_title()]
        for i in range(len(titles)):
            for k in range(i + 1, len(titles)):
                assert not overlap(titles[i].extents, titles[k].extents), size


@pytest.mark.parametrize("size", [(800, 1600), (1000, 1000), (1600, 1200), (1600, 800)])
def test_3d_text_stays_inside_the_picture_clear_of_the_inset_and_of_each_other(size):
    from raysim.render.field3d import MARGIN, field_plotter, inset_size, unit

    ds = equation_fieldmap(PaperDeformation(110.0, 33.0), n_theta=45, n_phi=90)
    pl = field_plotter(ds, "intensity", size)
    backend.screenshot(pl, None)
    boxes = {}
    for name in ("title", "notes", "bar_title"):
        box = [0.0] * 4
        pl.actors[name].GetBoundingBox(pl.renderer, box)  # about the text's anchor
        ax, ay = pl.actors[name].GetPositionCoordinate().GetComputedDisplayValue(pl.renderer)
        box = [box[0] + ax, box[1] + ax, box[2] + ay, box[3] + ay]
        boxes[name] = (box[0], box[2], box[1], box[3])  # x0, y0, x1, y1 from the lower left
        assert box[0] >= 0 and box[2] >= 0 and box[1] <= size[0] and box[3] <= size[1], (size, name, box)
        # readable: at least 10 px per line however the picture is shaped
        assert pl.actors[name].GetTextProperty().GetFontSize() >= 10
    bar = pl.scalar_bars["colour"]
    x, y = bar.GetPositionCoordinate().GetValue()[:2]
    w, h = bar.GetPosition2Coordinate().GetValue()[:2]
    boxes["bar"] = (x * size[0], y * size[1], (x + w) * size[0], (y + h) * size[1])
    iw, ih = inset_size(size)
    m = MARGIN * unit(size)
    boxes["inset"] = (m, m, m + iw, m + ih)
    names = list(boxes)
    for i in range(len(names)):
        for k in range(i + 1, len(names)):
            assert not overlap(boxes[names[i]], boxes[names[k]]), (size, names[i], names[k])
    assert "|" not in pl.actors["bar_title"].GetInput()  # VTK's font drops the bar
    pl.close()
