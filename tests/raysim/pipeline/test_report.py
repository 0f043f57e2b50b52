"""The HTML report: self-contained (embedded PNGs), the paper's figures in order, the run's
numbers recomputed from the maps, the scene text; and ``report()``'s simulate -> invert ->
draw wiring (with the engine and the solver stood in for by the linear equation)."""

from __future__ import annotations

import base64
import io
import re
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from raysim.errors import RaysimError
from raysim.pipeline import report as report_module
from raysim.render.backend import RenderError, colour_count
from raysim.surface.deformation import PaperDeformation, Zernike
from tests.examples import equation_fieldmap, surfacemap

ROOT = Path(__file__).resolve().parents[3]
D, F = 110.0, 33.0
ORDER = ["fig8a_deformation", "fig8b_ideal_amplitude", "fig8c_fa_sphere", "fig8d_fa_aperture",
         "fig9_equation", "fig10_recovered"]


def paper_field():
    text = (ROOT / "scenes" / "paper_go.toml").read_text()
    return equation_fieldmap(PaperDeformation(D, F), D, F, scene_name="paper_go", scene=text,
                             attrs={"deformation": "paper Eq. 8 x 1"})


def recovered_surface(N: int = 96):
    truth = PaperDeformation(D, F)
    return surfacemap(lambda x, y: 0.96 * truth(x, y) + 1e-5 * np.cos(x / 9.0), D, N=N, truth=truth, F=F,
                      attrs={"solver": "example", "boundary": "zero on the rim (the paper's assumption)",
                             "time_s": 1.5})


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    surface = recovered_surface()
    page = report_module.write_report(paper_field(), surface, out, timings={"simulate": 8.0, "invert": 1.5})
    return page, surface


def test_report_is_one_self_contained_page_with_the_papers_figures_in_order(written):
    page, _ = written
    text = page.read_text(encoding="utf-8")
    ids = re.findall(r'<figure id="([a-z0-9_]+)">', text)
    assert ids[:len(ORDER)] == ORDER
    images = re.findall(r'<img alt="[^"]*" src="([^"]+)"', text)
    assert len(images) == len(ids)
    for src in images:
        assert src.startswith("data:image/png;base64,")  # embedded: the page needs nothing beside it
        picture = imread(io.BytesIO(base64.b64decode(src.split(",", 1)[1])), format="png")
        assert picture.shape[0] >= 900 and picture.shape[1] >= 1200
        assert colour_count(picture) > 100
    for name in ids:  # and the same PNGs beside it
        assert (page.parent / "figures" / f"{name}.png").is_file()
    assert 'src="http' not in text and "<script" not in text


def test_report_states_the_runs_numbers_and_the_scene(written):
    page, surface = written
    text = page.read_text(encoding="utf-8")
    error, truth = surface["error"].values, surface["truth"].values
    inside = np.isfinite(truth)
    rms = np.sqrt(np.mean(error[inside] ** 2))
    rrms = rms / (truth[inside].max() - truth[inside].min())
    assert f"RMS {rms * 1e6:.2f} µm, RRMS = RMS / M = {100 * rrms:.2f} %" in text
    assert "zero on the rim (the paper&#x27;s assumption)" in text
    assert "time: simulate</th><td>8.0 s" in text and "time: invert</th><td>1.5 s" in text
    assert "time: draw the figures" in text
    assert "[[deformation]]" in text and 'type = &quot;paper&quot;' in text


def test_report_runs_simulate_invert_draw_and_writes_the_data(tmp_path, monkeypatch):
    import raysim.simulate

    calls = []

    def fake_simulate(scene, method="go", device="cpu", progress=None):
        calls.append(("simulate", scene.name, method))
        field = paper_field()
        field.attrs["seconds_total"] = 0.1
        return field

    def fake_inversion():
        def invert(field, solver=None, grid=None, refine=None, device="cpu"):
            calls.append(("invert", solver, grid, refine))
            return recovered_surface(N=grid or 64)
        return invert

    monkeypatch.setattr(raysim.simulate, "simulate", fake_simulate)
    monkeypatch.setattr(report_module, "inversion", fake_inversion)
    # draw only two figures: the wiring is under test here, the figures above
    monkeypatch.setattr(report_module, "_figures", lambda field, surface: [
        ("fig10_recovered", "Fig. 10", np.full((900, 1200, 3), 200, dtype=np.uint8))])
    page = report_module.report(ROOT / "scenes" / "paper_go.toml", tmp_path / "run", solver="fft", grid=48,
                                refine=0)
    assert calls == [("simulate", "paper_go", "go"), ("invert", "fft", 48, 0)]
    assert page == tmp_path / "run" / "report.html" and page.is_file()
    assert (tmp_path / "run" / "field.nc").is_file() and (tmp_path / "run" / "surface.nc").is_file()
    from raysim.maps.fieldmap import load

    assert load(tmp_path / "run" / "field.nc").attrs["scene_name"] == "paper_go"


def test_report_without_the_solver_fails_before_simulating(tmp_path, monkeypatch):
    import builtins

    import raysim.simulate

    real_import = builtins.__import__

    def no_solver(name, *args, **kwargs):
        if name == "solver.invert" or name.startswith("solver.invert"):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_solver)
    monkeypatch.setattr(raysim.simulate, "simulate", lambda *a, **k: pytest.fail("simulated first"))
    with pytest.raises(RenderError, match="needs the solver"):
        report_module.report(ROOT / "scenes" / "paper_go.toml", tmp_path / "run")
    assert not (tmp_path / "run").exists()


def test_report_from_a_fieldmap_without_inversion_draws_the_field_figures(tmp_path, monkeypatch):
    import raysim.simulate
    from raysim.maps.fieldmap import save

    monkeypatch.setattr(raysim.simulate, "simulate", lambda *a, **k: pytest.fail("simulated a FieldMap"))
    monkeypatch.setattr(report_module, "inversion", lambda: pytest.fail("inverted with --no-invert"))
    drawn = []
    monkeypatch.setattr(report_module, "_figures", lambda field, surface: drawn.append(surface) or [
        ("fig9_equation", "Fig. 9", np.full((900, 1200, 3), 200, dtype=np.uint8))])
    source = save(paper_field(), tmp_path / "scan.nc")
    page = report_module.report(source, tmp_path / "run", invert=False)
    assert drawn == [None]
    text = page.read_text(encoding="utf-8")
    assert "inversion</th><td>not run" in text
    assert not (tmp_path / "run" / "surface.nc").exists()


def test_fig9_compares_the_equation_within_panels_not_across_their_edges():
    from raysim.render import figures

    text = (ROOT / "scenes" / "panels_go.toml").read_text()
    field = equation_fieldmap(PaperDeformation(D, F), D, F, scene=text)
    truth = figures.scene_deformation(field)
    assert truth is not None and truth.layout is not None
    # along y = 0, a radial gap of every ring: a stencil straddling it would see two panels'
    # pistons (a Laplacian of order piston / h^2); within one panel, rigid errors have none
    x = np.linspace(-50.0, 50.0, 201)
    np.testing.assert_allclose(truth.laplacian(x, np.zeros_like(x)), 0.0, atol=1e-9)
    straddling = (truth(x, 0.01 + 0 * x) + truth(x, -0.01 + 0 * x) - 2 * truth(x, 0 * x)) / 1e-4
    assert np.nanmax(np.abs(straddling)) > 1e-2


def test_a_failed_report_leaves_the_earlier_one_whole(tmp_path, monkeypatch):
    """The report is built beside its folder and replaces it only when complete: a failure
    while drawing leaves the old page and data as they were, and no stray folder."""
    import raysim.simulate

    old = tmp_path / "run"
    old.mkdir()
    for name, text in (("report.html", "old page"), ("surface.nc", "old surface")):
        (old / name).write_text(text)
    monkeypatch.setattr(raysim.simulate, "simulate", lambda scene, **kw: paper_field())
    monkeypatch.setattr(report_module, "inversion", lambda: lambda field, **kw: recovered_surface(N=48))

    def broken(field, surface):
        raise RenderError("the renderer broke")

    monkeypatch.setattr(report_module, "_figures", broken)
    with pytest.raises(RenderError, match="broke"):
        report_module.report(ROOT / "scenes" / "paper_go.toml", old)
    assert sorted(p.name for p in old.iterdir()) == ["report.html", "surface.nc"]
    assert (old / "report.html").read_text() == "old page"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
    # options are checked before any simulation
    monkeypatch.setattr(raysim.simulate, "simulate", lambda *a, **k: pytest.fail("simulated first"))
    with pytest.raises(RaysimError, match="unknown solver"):
        report_module.report(ROOT / "scenes" / "paper_go.toml", old, solver="magic")
    monkeypatch.setattr(report_module, "_figures", lambda field, surface: [
        ("fig10_recovered", "Fig. 10", np.full((90, 120, 3), 200, dtype=np.uint8))])
    monkeypatch.setattr(raysim.simulate, "simulate", lambda scene, **kw: paper_field())
    report_module.report(ROOT / "scenes" / "paper_go.toml", old, invert=False)
    assert not (old / "surface.nc").exists() and (old / "field.nc").is_file()  # no stale surface


# --- the paper's row: the paper's own figure for the same kind of data, naming its table --------
def paper_row(method: str, frequency_hz: float, deformation: str = "paper Eq. 8 x 1") -> str | None:
    """The page's "paper" row for the paper's dish and sphere with data of ``method`` at
    ``frequency_hz`` (None: no such row)."""
    field = paper_field()
    field.attrs.update(method=method, frequency_hz=frequency_hz, deformation=deformation)
    return dict(report_module.numbers(field, recovered_surface(N=48), {})).get("paper")


def test_the_paper_row_quotes_the_papers_figure_for_the_same_kind_of_data(written, tmp_path, monkeypatch):
    go = paper_row("go", 0.3e9)  # the paper's GO case: FDM 4.06 %, FFT 7.47 %
    assert "GO data" in go and "Table 2" in go and "4.06 %" in go and "7.47 %" in go
    assert "Table 3" not in go
    # the paper's Table 3 (PO & PTD data): 0.1 GHz RMS 264.84 um, RRMS 22.07 %; 3 GHz 77.04 um, 6.42 %
    po = paper_row("po", 0.1e9)
    assert "Table 3" in po and "0.1 GHz" in po and "264.84 µm" in po and "22.07 %" in po
    assert "4.06" not in po and "GO data" not in po
    ptd = paper_row("po+ptd", 3e9)
    assert "Table 3" in ptd and "3 GHz" in ptd and "77.04 µm" in ptd and "6.42 %" in ptd
    # the paper has no figure for these: a frequency Table 3 does not list, other data, another
    # deformation
    assert paper_row("po", 0.2e9) is None
    assert paper_row("po+ptd", 0.3e9 * 1.01) is None
    assert paper_row("go+edge", 0.3e9) is None
    assert paper_row("go", 0.3e9, deformation="paper Eq. 8 x 2") is None
    # on the pages: the GO report quotes the GO case only, a PO report at 0.1 GHz Table 3 only
    go_page = written[0].read_text(encoding="utf-8")
    assert "4.06 %" in go_page and "Table 3" not in go_page
    field = paper_field()
    field.attrs.update(method="po", frequency_hz=0.1e9)
    po_page = page_text(field, recovered_surface(N=48), tmp_path, monkeypatch)
    assert "22.07 %" in po_page and "Table 3" in po_page and "4.06" not in po_page


# --- what the data cannot determine -----------------------------------------------------------
def page_text(field, surface, out, monkeypatch) -> str:
    """The report page (unescaped) of ``field`` and ``surface`` without its figures."""
    import html

    monkeypatch.setattr(report_module, "_figures", lambda field, surface: [])
    return html.unescape(report_module.write_report(field, surface, out).read_text(encoding="utf-8"))


def limits_paragraph(text: str) -> str:
    """The page's paragraph on what the data cannot determine, checked to stand beside the
    headline accuracy, before the table of numbers."""
    match = re.search(r'<p class="limits">(.*?)</p>', text, re.S)
    assert match is not None
    assert text.index("RMS error") < match.start() < text.index("Numbers of this run")
    return match.group(1)


ASTIGMATISM = Zernike(((2, 2, 100e-6),), D / 2)  # r^2 cos 2 phi: harmonic, no Laplacian, no FA


def test_the_page_says_the_error_of_astigmatism_is_the_unobservable_harmonic_part(tmp_path, monkeypatch):
    from solver.invert import invert
    from solver.run import summary

    field = equation_fieldmap(ASTIGMATISM, D, F, n_theta=45, n_phi=90)
    surface = invert(field, N=64, truth=ASTIGMATISM, refine_iterations=0)
    error = surface["error"].values
    err_um = np.sqrt(np.nanmean(error**2)) * 1e6
    assert err_um > 90  # the intensities see nothing of it: the whole deformation is the error
    text = page_text(field, surface, tmp_path, monkeypatch)
    limits = limits_paragraph(text)
    # the sentence raysim invert prints, and how to fix it
    said = next(line for line in summary(surface) if line.startswith("harmonic part"))
    assert said[1:] in limits
    assert "tilt, astigmatism, any r^n cos n phi) is UNOBSERVABLE without rim targets" in limits
    assert "Rim targets fix it" in limits and "--rim" in limits
    # and how much of the error it is: all of it, astigmatism being harmonic
    row = re.search(r"harmonic part of the truth</th><td>RMS ([\d.]+) µm .*?the error without it: RMS "
                    r"([\d.]+) µm", text)
    assert row is not None
    assert float(row.group(1)) == pytest.approx(err_um, rel=0.01)
    assert float(row.group(2)) < 0.01 * err_um


def test_with_rim_targets_the_page_says_they_fixed_the_harmonic_part(tmp_path, monkeypatch):
    from solver.boundary import RimTargets
    from solver.invert import invert

    field = equation_fieldmap(ASTIGMATISM, D, F, n_theta=45, n_phi=90)
    phi = np.linspace(0.0, 2 * np.pi, 24, endpoint=False)
    x, y = 0.98 * D / 2 * np.cos(phi), 0.98 * D / 2 * np.sin(phi)
    surface = invert(field, N=64, truth=ASTIGMATISM, refine_iterations=0,
                     rim=RimTargets(x, y, ASTIGMATISM(x, y)))
    text = page_text(field, surface, tmp_path, monkeypatch)
    limits = limits_paragraph(text)
    assert "fixed here by rim targets" in limits and "24 points" in limits
    assert "UNOBSERVABLE" not in limits and "--rim" not in limits
    assert "harmonic part of the truth" not in text


A = D / 2


@pytest.mark.parametrize("harmonic", [
    lambda x, y: 0.0 * x,                                          # zero on the rim: none of it
    lambda x, y: 20e-6 * (x * x - y * y) / A**2 + 5e-6 * x / A,    # astigmatism and tilt
], ids=["zero-on-the-rim", "harmonic"])
def test_the_truths_harmonic_part_is_what_a_map_without_rim_targets_misses(harmonic):
    """A map that recovers the paper's deformation (zero on the rim) to within a small error
    of its own, of a truth that also holds a harmonic shape: the report finds the harmonic
    shape's RMS, and the map's own error once it is taken out."""
    paper = PaperDeformation(D, F)

    def truth(x, y):
        return paper(x, y) + harmonic(x, y)

    own = lambda x, y: 20e-6 * np.sin(3 * x / A) * (1 - (x * x + y * y) / A**2)  # noqa: E731
    surface = surfacemap(lambda x, y: paper(x, y) + own(x, y), D, N=128, truth=truth, F=F)
    X, Y = np.meshgrid(surface["x"].values, surface["y"].values)
    inside = np.isfinite(surface["error"].values)
    truth_rms = np.sqrt(np.mean(truth(X, Y)[inside] ** 2))
    expected_part = np.sqrt(np.mean(harmonic(X, Y)[inside] ** 2))
    expected_rest = np.sqrt(np.mean(own(X, Y)[inside] ** 2))
    part, rest = report_module.harmonic_error(surface)
    # the fit reads the ring of cells inside the rim, where Eq. 8 is not quite zero: within
    # 1 % of the truth, the report's threshold for naming a figure
    assert part == pytest.approx(expected_part, abs=0.01 * truth_rms)
    assert report_module._sizeable(part, surface) == (expected_part > 0)
    assert rest == pytest.approx(expected_rest, rel=0.1)


# --- the figures as the page shows them -------------------------------------------------------
SHOWN_WIDTH = 1246  # px of a figure on the page in a 1280 px window (body padding, border off)


def text_bands(image: np.ndarray, rows: slice, cols: slice) -> list[tuple[int, int]]:
    """(first, last) rows of each run of rows holding black or grey text in image[rows, cols]."""
    rgb = image[rows, cols, :3].astype(np.int64)
    grey_dark = (rgb.max(axis=-1) < 110) & (rgb.max(axis=-1) - rgb.min(axis=-1) < 25)
    hit = np.nonzero(grey_dark.sum(axis=1) > 0)[0]
    bands: list[list[int]] = []
    for r in hit:
        if bands and r == bands[-1][1] + 1:
            bands[-1][1] = r
        else:
            bands.append([r, r])
    return [(first + (rows.start or 0), last + (rows.start or 0)) for first, last in bands]


def bar_rows(image: np.ndarray, rows: slice, cols: slice) -> tuple[int, int]:
    """First and last rows of a horizontal colour bar in image[rows, cols]: rows mostly coloured."""
    rgb = image[rows, cols, :3].astype(np.int64)
    coloured = (rgb.max(axis=-1) - rgb.min(axis=-1)) > 40
    hit = np.nonzero(coloured.mean(axis=1) > 0.3)[0]
    return hit[0] + (rows.start or 0), hit[-1] + (rows.start or 0)


@pytest.mark.parametrize("name, panels", [("surface_3d", 3), ("fig8a_deformation", 1)])
def test_3d_colour_bars_keep_their_title_off_the_tick_labels(written, name, panels):
    image = (imread(written[0].parent / "figures" / f"{name}.png") * 255).astype(np.uint8)
    height, width = image.shape[:2]
    scale = SHOWN_WIDTH / width
    for k in range(panels):
        # the middle 80 % of the panel's width, the bottom 20 % of the picture: its colour bar
        cols = slice(int((k + 0.1) * width / panels), int((k + 0.9) * width / panels))
        rows = slice(int(0.8 * height), height)
        top, bottom = bar_rows(image, rows, cols)
        bands = text_bands(image, rows, cols)
        above = [b for b in bands if b[1] < top]
        below = [b for b in bands if b[0] > bottom]
        assert len(above) == 1 and len(below) == 1, bands  # labels above the bar, its title below
        assert not [b for b in bands if b[1] >= top and b[0] <= bottom]
        labels, title = above[0], below[0]
        # legible where the page shows the picture: digits' height, a line with (µm)'s height
        assert (labels[1] - labels[0] + 1) * scale >= 8.0
        assert (title[1] - title[0] + 1) * scale >= 11.0


def test_wide_maps_text_reads_at_the_pages_width(written):
    image = (imread(written[0].parent / "figures" / "surface_maps.png") * 255).astype(np.uint8)
    height, width = image.shape[:2]
    assert width == 2400
    # each panel's colour bar label, the lowest line of text: a line with "(µm)" in it
    for k in range(3):
        cols = slice(int(k * width / 3), int((k + 1) * width / 3))
        label = text_bands(image, slice(int(0.85 * height), height), cols)[-1]
        assert (label[1] - label[0] + 1) * SHOWN_WIDTH / width >= 10.0  # 7 px before


def test_fig9_legend_hides_no_curve():
    from raysim.render import figures

    field = paper_field()
    x = figures.aperture_x(field, None)
    fig = figures.fig9_equation(field, x, figures.truth_laplacian(figures.scene_deformation(field), None))
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    legends = fig.legends + [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    assert legends
    for legend in legends:
        box = legend.get_window_extent(renderer)
        assert {t.get_text() for t in legend.get_texts()} == {"FA from the intensities",
                                                              "G Laplacian(delta), true delta"}
        for ax in fig.axes:  # outside every plot: no stretch of a curve under it
            assert not box.overlaps(ax.get_window_extent(renderer))


COARSE_SCENE = """
name = "coarse"
[dish]
diameter_m = 110.0
focal_length_m = 33.0
resolution_m = 2.0
[source]
frequency_hz = 0.3e9
[sphere]
radius_m = 10.0
n_theta = 45
n_phi = 90
"""


@pytest.mark.parametrize("options, line", [
    (["--n-theta", "12", "--n-phi", "24", "--frequency", "0.6e9"],
     "This run overrode the scene text:</strong> sphere grid 12 x 24 cells (theta x phi; the text "
     "says 45 x 90); frequency 0.6 GHz (the text says 0.3 GHz) (read from the FieldMap)."),
    (["--n-theta", "12"], "sphere grid 12 x 90 cells (theta x phi; the text says 45 x 90) (read"),
    ([], None),
])
def test_the_scene_section_names_what_simulate_overrode(raysim_cli, tmp_path, monkeypatch, options,
                                                         line):
    """QA: after simulate --n-theta 30 --n-phi 60 the report printed the scene text (90 x 360)
    alone beside 30 x 60 data. The line under it is read from the FieldMap's grid and
    attributes; a run that overrode nothing gets none."""
    monkeypatch.setattr(report_module, "_figures", lambda field, surface: [
        ("fig9_equation", "Fig. 9", np.full((90, 120, 3), 200, dtype=np.uint8))])
    scene = tmp_path / "coarse.toml"
    scene.write_text(COARSE_SCENE)
    field = tmp_path / "fm.nc"
    code, _, err = raysim_cli("simulate", scene, "-o", field, *options)
    assert code == 0, err
    code, _, err = raysim_cli("report", field, "-o", tmp_path / "rep", "--no-invert")
    assert code == 0, err
    page = (tmp_path / "rep" / "report.html").read_text(encoding="utf-8")
    assert "n_theta = 45" in page  # the scene as written stays
    if line is None:
        assert "overrode" not in page
    else:
        assert line in page


def test_the_inversions_warnings_are_on_the_page_and_the_console(raysim_cli, tmp_path, monkeypatch):
    """QA: invert warned "do not act on it" for a scan, and the report of the same scan said
    nothing, on the page or where it ran. Cells of 7.5 x 15 deg on the paper's dish are too
    coarse to resolve the surface (solver.record.sampling_attrs): both say so now; the same
    scene on 3 x 6 deg cells gets no warning box. The scene's dish is ideal: its flat truth
    (M = 0) made the report raise ZeroDivisionError for the RRMS."""
    monkeypatch.setattr(report_module, "_figures", lambda field, surface: [])
    scene = tmp_path / "coarse.toml"
    scene.write_text(COARSE_SCENE)
    pages = {}
    for cells in ((12, 24), (30, 60)):
        field = tmp_path / f"fm{cells[0]}.nc"
        code, _, err = raysim_cli("simulate", scene, "-o", field, "--n-theta", str(cells[0]),
                                  "--n-phi", str(cells[1]))
        assert code == 0, err
        code, out, err = raysim_cli("report", field, "-o", tmp_path / f"rep{cells[0]}", "--grid", "64",
                                    "--refine", "0")
        assert code == 0, err
        pages[cells[0]] = (out, (tmp_path / f"rep{cells[0]}" / "report.html").read_text(encoding="utf-8"))
    out, page = pages[12]
    assert "WARNING: inversion: the scan's cells meet the dish up to" in out
    box = re.search(r'<div class="warnings">(.*?)</div>', page, re.S)
    assert box is not None and "inversion: the scan&#x27;s cells meet the dish" in box.group(1)
    assert page.index('class="warnings"') < page.index("Numbers of this run")
    out, page = pages[30]
    assert "WARNING" not in out and 'class="warnings"' not in page
