"""``raysim invert``: files in, files out, one clear line and exit status 2 on user errors."""

import numpy as np
import pytest

from raysim.maps.fieldmap import save
from solver import surface
from tests.cli import run_in_process


def run(monkeypatch, capsys, *args):
    return tuple(run_in_process(capsys, *args))


@pytest.fixture(scope="module")
def field_file(tmp_path_factory, request):
    paper_field = request.getfixturevalue("paper_field")
    return save(paper_field, tmp_path_factory.mktemp("cli") / "paper.nc")


def test_invert_writes_a_surface_map_and_says_what_it_assumed(monkeypatch, capsys, tmp_path,
                                                             field_file):
    out = tmp_path / "surface.nc"
    code, stdout, _ = run(monkeypatch, capsys, "invert", str(field_file), "-o", str(out),
                          "--grid", "64", "--refine", "0", "--remove", "piston,tilt")
    assert code in (0, None)
    result = surface.load(out)
    assert result.sizes["x"] == 64 and result.attrs["removed_terms"] == "piston,tilt"
    assert "UNOBSERVABLE" in stdout and "boundary: zero on the rim" in stdout
    assert "truth unknown" in stdout and "time" in stdout
    assert np.isfinite(result["deformation"].values).sum() == surface.grid_of(result).n_inside


def test_rim_targets_from_csv_reach_the_map(monkeypatch, capsys, tmp_path, field_file):
    phi = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    rows = "\n".join(f"{55 * np.cos(p):.4f},{55 * np.sin(p):.4f},0.0" for p in phi)
    rim = tmp_path / "rim.csv"
    rim.write_text("x,y,dz\n" + rows + "\n")
    out = tmp_path / "surface.nc"
    code, stdout, _ = run(monkeypatch, capsys, "invert", str(field_file), "-o", str(out),
                          "--grid", "64", "--refine", "0", "--rim", str(rim))
    assert code in (0, None)
    assert "UNOBSERVABLE" not in stdout and "rim targets: 16 points" in stdout
    assert surface.load(out).attrs["harmonic_part"] == "fixed by rim targets"


@pytest.mark.parametrize("case", ["missing", "units", "solver", "grid", "rim", "terms", "panels"])
def test_user_errors_end_with_one_line_and_status_2(monkeypatch, capsys, tmp_path, field_file,
                                                     paper_field, case):
    args = [str(field_file), "-o", str(tmp_path / "s.nc"), "--refine", "0", "--grid", "32"]
    if case == "missing":
        args[0] = str(tmp_path / "absent.nc")
    elif case == "units":
        bad = paper_field.copy(deep=True)
        bad["theta"].attrs["units"] = "deg"
        bad.to_netcdf(tmp_path / "deg.nc")
        args[0] = str(tmp_path / "deg.nc")
    elif case == "solver":
        args += ["--solver", "cholesky"]
    elif case == "grid":
        args[-1] = "8"
    elif case == "rim":
        (tmp_path / "rim.csv").write_text("x,y,dz\n1,2,3\n4,five,6\n")
        args += ["--rim", str(tmp_path / "rim.csv")]
    elif case == "terms":
        args += ["--remove", "piston,coma"]
    elif case == "panels":
        args += ["--panels-csv", str(tmp_path / "panels.csv")]
    code, stdout, stderr = run(monkeypatch, capsys, "invert", *args)
    assert code == 2
    assert stderr.startswith("error:") and len(stderr.strip().splitlines()) == 1, stderr
    assert "Traceback" not in stderr + stdout
    assert not (tmp_path / "s.nc").exists()


def test_panels_csv_from_a_fieldmap_whose_scene_has_panels(monkeypatch, capsys, tmp_path,
                                                           paper_field):
    """The layout comes from the scene the FieldMap records (here: scenes/panels_go.toml)."""
    from pathlib import Path

    scene = (Path(__file__).resolve().parents[2] / "scenes" / "panels_go.toml").read_text()
    field = paper_field.copy(deep=True).assign_attrs(scene=scene)
    path = save(field, tmp_path / "panels.nc")
    table = tmp_path / "panels.csv"
    code, _, _ = run(monkeypatch, capsys, "invert", str(path), "-o", str(tmp_path / "s.nc"),
                     "--grid", "128", "--refine", "0", "--panels-csv", str(table))
    assert code in (0, None)
    lines = table.read_text().splitlines()
    assert lines[0].startswith("panel_id,ring,centre_x_m,centre_y_m,tilt_x_urad")
    assert len(lines) == 1 + 216


def test_paper_po_sweep_reproduces_table3_at_0p1_ghz_and_keeps_its_fieldmap(monkeypatch, capsys,
                                                                          tmp_path):
    """`raysim paper --po` at 0.1 GHz (the cheapest Table 3 row): the paper's setting on the
    project's PO + PTD data lands near the paper's 22.07 %; the FieldMap is kept and reused."""
    from raysim.maps.fieldmap import load

    fields = tmp_path / "fields"
    code, stdout, _ = run(monkeypatch, capsys, "paper", "--po", "--frequencies", "0.1e9",
                          "--grid", "64", "--refine", "1", "--fields", str(fields))
    assert code in (0, None)
    row = next(line.split() for line in stdout.splitlines() if line.strip().startswith("0.1 "))
    # f, 90 x 360, paper RMS, paper RRMS %, RMS, RRMS %, GO RMS, GO RRMS %, wave RMS, wave RRMS %
    rrms = float(row[8])
    assert abs(rrms - 22.07) / 22.07 < 0.25
    assert np.isfinite(float(row[10])) and np.isfinite(float(row[13]))
    kept = load(fields / "paper_poptd_0.1GHz_90x360.nc")
    assert kept.attrs["method"] == "po+ptd"

    code, stdout, err = run(monkeypatch, capsys, "paper", "--po", "--frequencies", "0.1e9",
                            "--grid", "32", "--refine", "0", "--fields", str(fields))
    assert code in (0, None) and "read" in err + stdout
    row = next(line.split() for line in stdout.splitlines() if line.strip().startswith("0.1 "))
    assert row[-3] == "-"                         # no wave row without refinement


def test_paper_po_rejects_bad_frequencies(monkeypatch, capsys):
    code, _, err = run(monkeypatch, capsys, "paper", "--po", "--frequencies", "0.1e9,abc")
    assert code == 2 and err.count("\n") == 1 and "--frequencies" in err


def test_run_invert_from_python_refuses_to_write_over_its_inputs(tmp_path, field_file):
    """The API writes nothing over its inputs either (it replaced the FieldMap with a
    SurfaceMap, and the rim CSV with NetCDF, where the CLI refused)."""
    import shutil

    from raysim.errors import RaysimError
    from solver.run import run_invert

    field = shutil.copy(field_file, tmp_path / "in.nc")
    rim = tmp_path / "rim.csv"
    rim.write_text("x,y,dz\n" + "\n".join(f"{55 * np.cos(p):.4f},{55 * np.sin(p):.4f},0.0"
                                           for p in np.linspace(0, 6, 8)) + "\n")
    before = {p: p.read_bytes() for p in (tmp_path / "in.nc", rim)}
    for output, extra in ((field, {}), (rim, {"rim_csv": rim}),
                          (tmp_path / "s.nc", {"panels_csv": field}),
                          (tmp_path / "s.nc", {"panels_csv": tmp_path / "s.nc"})):
        with pytest.raises(RaysimError, match="would destroy the input"):
            run_invert(field, output, N=32, refine=0, **extra)
    assert {p: p.read_bytes() for p in before} == before
    assert not (tmp_path / "s.nc").exists()
