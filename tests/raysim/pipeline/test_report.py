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
from raysim.surface.deformation import PaperDeformation
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
