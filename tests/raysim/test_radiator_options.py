"""The fast radiator's tolerance: ``raysim paper --po`` takes --radiator-tol as simulate,
invert and check do; a FieldMap records ``radiator_tol`` only where the fast radiator was asked
for."""

from __future__ import annotations

import pytest
import xarray as xr

from raysim.maps.fieldmap import load, save
from raysim.scene.scene import parse_scene
from raysim.simulate import simulate
from tests.cli import run_in_process
from tests.raysim.distributed.conftest import SMALL

# the paper's dish at 20 MHz on its 90 x 360 sphere: a PO + PTD FieldMap in a few seconds
PAPER_PO = ("paper", "--po", "--frequencies", "0.02e9", "--grid", "16", "--refine", "1")
KEPT = "paper_poptd_0.02GHz_90x360.nc"
KEPT_AT_1E_4 = "paper_poptd_0.02GHz_90x360_fast_tol0.0001.nc"


# --- raysim paper --radiator-tol ------------------------------------------------------------
@pytest.mark.parametrize("value", ["0", "-1", "2", "nan", "inf", "1e-13", "abc"])
def test_paper_refuses_a_bad_radiator_tol_in_one_line(capsys, value):
    result = run_in_process(capsys, "paper", "--po", "--radiator-tol", value)
    assert result.code == 2
    assert ("Invalid value for '--radiator-tol'" if value == "abc" else
            "--radiator-tol must lie in [1e-12, 1)") in result.error()


@pytest.mark.parametrize(("args", "says"), [
    (("--radiator-tol", "1e-3"), "--radiator-tol applies"),
    (("--radiator", "direct"), "--radiator applies"),
    (("--frequencies", "1e9", "--radiator", "fast"), "--frequencies, --radiator apply"),
])
def test_paper_refuses_the_sweeps_options_without_po(capsys, args, says):
    """The GO case sums no fields and sweeps no frequencies: these options were taken and did
    nothing (all but --radiator-tol)."""
    result = run_in_process(capsys, "paper", *args)
    assert result.code == 2
    assert result.error().endswith(f"{says} to --po only")


@pytest.fixture
def spied(monkeypatch):
    """Every tolerance the PO + PTD sources hand the radiator, and every inversion's keywords
    (the inversions replaced by a stand-in: only their options matter here)."""
    from raysim.optics import sources
    from raysim.pipeline import paper

    tols: list[float] = []
    inversions: list[dict] = []
    make_radiator = sources.make_radiator

    def radiator(*args, **kwargs):
        tols.append(kwargs["tol"])
        return make_radiator(*args, **kwargs)

    def invert(field, **kwargs):
        inversions.append(kwargs)
        return xr.Dataset(attrs={"rms_m": 1e-4, "rrms": 0.1})

    monkeypatch.setattr(sources, "make_radiator", radiator)
    monkeypatch.setattr(paper, "invert", invert)
    return tols, inversions


def test_paper_po_sums_the_data_and_the_wave_refinement_to_the_radiator_tol(capsys, tmp_path, spied):
    from raysim.optics.fast.radiator import DEFAULT_TOL

    tols, inversions = spied
    fields = tmp_path / "fields"
    result = run_in_process(capsys, *PAPER_PO, "--fields", fields, "--radiator-tol", "1e-4")
    assert result.code == 0, result.stderr
    assert tols and set(tols) == {1e-4}
    kept = load(fields / KEPT_AT_1E_4)
    assert (kept.attrs["radiator"], kept.attrs["radiator_tol"]) == ("fast", 1e-4)
    wave = [kw for kw in inversions if "radiator" in kw]  # the PO + PTD model's refinement
    assert [(kw["radiator"], kw["radiator_tol"]) for kw in wave] == [("fast", 1e-4)]

    # the kept FieldMap is reused at its own tolerance; the default's sums keep their own file
    tols.clear()
    result = run_in_process(capsys, *PAPER_PO, "--fields", fields, "--radiator-tol", "1e-4")
    assert result.code == 0 and tols == []
    before = (fields / KEPT_AT_1E_4).read_bytes()
    result = run_in_process(capsys, *PAPER_PO, "--fields", fields)
    assert result.code == 0, result.stderr
    assert tols and set(tols) == {DEFAULT_TOL}
    assert load(fields / KEPT).attrs["radiator_tol"] == DEFAULT_TOL
    assert (fields / KEPT_AT_1E_4).read_bytes() == before


def test_paper_po_leaves_a_kept_fieldmap_summed_otherwise_as_it_is(capsys, tmp_path, spied):
    """A file of the kept name that does not say how it was summed (or was summed otherwise)
    is not taken as the run's data, nor replaced."""
    fields = tmp_path / "fields"
    result = run_in_process(capsys, *PAPER_PO, "--fields", fields)
    assert result.code == 0, result.stderr
    odd = load(fields / KEPT)
    del odd.attrs["radiator"]
    save(odd, fields / KEPT)
    before = (fields / KEPT).read_bytes()
    tols, _ = spied
    tols.clear()
    result = run_in_process(capsys, *PAPER_PO, "--fields", fields)
    assert result.code == 0, result.stderr
    assert tols  # simulated again
    assert "radiator not recorded): left as it is" in result.stderr
    assert (fields / KEPT).read_bytes() == before


# --- what a FieldMap records ------------------------------------------------------------------
@pytest.fixture(scope="module")
def small():
    return parse_scene(SMALL, source="small")


def _saved(ds: xr.Dataset, path) -> dict:
    return dict(load(save(ds, path)).attrs)


def test_a_direct_sum_fieldmap_records_no_tolerance(small, tmp_path):
    """The direct sum has no tolerance: the file said 1e-6 (or whatever was given) as if it
    had applied."""
    attrs = _saved(simulate(small, "po", radiator="direct", radiator_tol=1e-3), tmp_path / "d.nc")
    assert (attrs["radiator"], attrs["radiator_ran"]) == ("direct", "direct")
    assert "radiator_tol" not in attrs


def test_a_fast_radiator_fieldmap_records_its_tolerance(small, tmp_path):
    attrs = _saved(simulate(small, "po", radiator="fast", radiator_tol=1e-3), tmp_path / "f.nc")
    assert attrs["radiator"] == "fast" and attrs["radiator_tol"] == 1e-3
    assert attrs["radiator_ran"]


def test_a_go_fieldmap_records_no_radiator(small, tmp_path):
    attrs = _saved(simulate(small, "go"), tmp_path / "g.nc")
    assert not {"radiator", "radiator_tol", "radiator_ran"} & set(attrs)
