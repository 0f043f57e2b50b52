"""``raysim render``: PNGs of the asked size from either contract, one-line errors with exit
status 2, and a clean process with no DISPLAY and no VTK setting renders 3D through EGL."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from matplotlib.image import imread

from raysim.maps.fieldmap import save
from raysim.render import RenderError, parse_size, render
from raysim.render.backend import colour_count
from raysim.surface.deformation import GaussianBumps
from tests.cli import Result, run_in_process
from tests.cli import run_cli as run_cli_process
from tests.examples import equation_fieldmap, surfacemap

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("maps")
    bump = GaussianBumps(((10.0, 5.0, 200e-6, 5.0),))
    field = save(equation_fieldmap(bump, n_theta=45, n_phi=180), folder / "field.nc")
    surface = folder / "surface.nc"
    surfacemap(bump, N=64).to_netcdf(surface)
    return field, surface


def run_cli(monkeypatch, capsys, *args: str) -> tuple[int, str, str]:
    return tuple(run_in_process(capsys, *args))


def test_render_writes_a_png_of_the_asked_size(monkeypatch, capsys, files, tmp_path):
    field, surface = files
    out = tmp_path / "field_map.png"
    code, stdout, _ = run_cli(monkeypatch, capsys, "render", str(field), "-o", str(out), "--kind", "map",
                              "--size", "1300x950", "--quantity", "normalized")
    assert code == 0 and str(out) in stdout
    assert imread(out).shape[:2] == (950, 1300)
    out = tmp_path / "surface.png"
    code, _, _ = run_cli(monkeypatch, capsys, "render", str(surface), "-o", str(out))
    assert code == 0
    image = imread(out)
    assert image.shape[:2] == (1200, 1600)  # the default size
    assert colour_count(image) > 100


@pytest.mark.parametrize("args, message", [
    (["--size", "12"], "--size must look like"),
    (["--size", "100x100"], "outside"),
    (["--kind", "4d"], "unknown kind '4d'"),
    (["--quantity", "phase"], "unknown quantity 'phase'"),
])
def test_bad_options_end_with_one_line_and_status_2(monkeypatch, capsys, files, tmp_path, args, message):
    code, _, err = run_cli(monkeypatch, capsys, "render", str(files[0]), "-o", str(tmp_path / "x.png"), *args)
    assert code == 2
    assert message in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.png").exists()


def test_unreadable_or_foreign_files_end_with_status_2(monkeypatch, capsys, tmp_path):
    garbage = tmp_path / "garbage.nc"
    garbage.write_text("not netcdf")
    foreign = tmp_path / "foreign.nc"
    import xarray as xr

    xr.Dataset({"a": ("q", [1.0, 2.0])}).to_netcdf(foreign)
    for path, message in ((tmp_path / "missing.nc", "no such file"), (garbage, "not a readable NetCDF"),
                          (foreign, "neither a FieldMap")):
        code, _, err = run_cli(monkeypatch, capsys, "render", str(path), "-o", str(tmp_path / "x.png"))
        assert code == 2, err
        assert message in err and len(err.strip().splitlines()) == 1
    # a missing input leaves no trace: the output's folder is not made for it
    code, _, err = run_cli(monkeypatch, capsys, "render", str(tmp_path / "missing.nc"),
                           "-o", str(tmp_path / "new" / "x.png"))
    assert code == 2 and "no such file" in err
    assert not (tmp_path / "new").exists()


def test_api_checks_the_output_name_and_sizes(files, tmp_path):
    with pytest.raises(RenderError, match="PNG"):
        render(files[0], tmp_path / "x.jpg")
    assert parse_size("1600x1200", (1, 1)) == (1600, 1200)
    assert parse_size(None, (1200, 900)) == (1200, 900)
    assert parse_size((1400, 1000), (1, 1)) == (1400, 1000)
    with pytest.raises(RenderError):
        parse_size("1600 by 1200", (1, 1))


def test_3d_renders_in_a_process_with_no_display_and_no_vtk_setting(files, tmp_path):
    unset = ("DISPLAY", "WAYLAND_DISPLAY", "VTK_DEFAULT_OPENGL_WINDOW", "PYVISTA_OFF_SCREEN")
    env = {k: v for k, v in os.environ.items() if k not in unset}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    out = tmp_path / "field3d.png"
    code = ("import sys; from raysim.render import render; "
            "render(sys.argv[1], sys.argv[2], kind='3d', size='1200x900'); "
            "import vtk; print(vtk.vtkRenderWindow().GetClassName())")
    done = subprocess.run([sys.executable, "-c", code, str(files[0]), str(out)], env=env, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().endswith("vtkEGLRenderWindow")
    image = imread(out)
    assert image.shape[:2] == (900, 1200)
    assert colour_count(image) > 1000


def test_missing_egl_is_one_clear_error_not_a_crash(monkeypatch):
    """Without libEGL (or without a driver behind it) VTK's EGL window crashes the process;
    the probe turns that into a RenderError naming what to install."""
    import ctypes

    from raysim.render import backend

    assert backend.egl_available()  # this machine renders: the tests above need it

    def no_library(name, *args, **kwargs):
        raise OSError(f"{name}: cannot open shared object file")

    monkeypatch.setattr(ctypes, "CDLL", no_library)
    backend.egl_available.cache_clear()
    try:
        assert not backend.egl_available()
        with pytest.raises(RenderError, match="libegl1 libegl-mesa0 libgl1-mesa-dri"):
            backend.pyvista()
    finally:
        monkeypatch.undo()
        backend.egl_available.cache_clear()
    assert backend.egl_available()


@pytest.fixture(scope="module")
def zarr_folder(tmp_path_factory):
    """A Zarr store without consolidated metadata: xarray warned (five lines) on opening it."""
    import xarray as xr

    store = tmp_path_factory.mktemp("store") / "w1.zarr"
    xr.Dataset({"intensity": (("theta", "phi"), [[1.0, 2.0]])},
               coords={"theta": [10.0], "phi": [0.0, 90.0]}).to_zarr(store, consolidated=False)
    return store


@pytest.mark.parametrize("command", [
    ["render", "-o", "{out}/x.png"],
    ["report", "-o", "{out}/rep", "--grid", "16", "--refine", "0"],
    ["invert", "-o", "{out}/s.nc", "--grid", "16", "--refine", "0"],
    ["invert", "-o", "{out}/s.nc", "--radiator", "fast", "--model", "po"],
    ["correct", "-o", "{out}/corr"],
    ["scan", "scan_demo", "-o", "{out}/scan.nc", "--simulate"],
])
@pytest.mark.parametrize("what", ["zarr", "empty", "missing"])
def test_a_folder_or_missing_map_gets_its_one_line_and_nothing_before(raysim_cli, zarr_folder,
                                                                      tmp_path, command, what):
    """Every command that reads a FieldMap or SurfaceMap: stderr is the reader's one line (a
    Zarr folder was opened before the folder check, and xarray printed five lines first)."""
    given = {"zarr": zarr_folder, "empty": tmp_path / "empty.nc", "missing": tmp_path / "no.nc"}[what]
    if what == "empty":
        given.mkdir()
    out = tmp_path / "out"
    args = [a.format(out=out) for a in command]
    # the map is the command's argument, or the value of its last option (scan --simulate)
    args = [*args, str(given)] if args[-1].startswith("--simulate") else [args[0], str(given), *args[1:]]
    # a subprocess for the Zarr store: in this process pytest takes xarray's warning for itself
    code, stdout, stderr = run_cli_process(*args) if what == "zarr" else raysim_cli(*args)
    assert code == 2, stderr
    line = Result(code, stdout, stderr).error()  # exactly one line on stderr
    assert line.startswith(f"error: {given}: is a folder, give a " if what != "missing" else
                           f"error: {given}: no such file"), line
    # nothing written (render makes the output's folder before it reads: that stays empty)
    assert not out.exists() or not any(p.is_file() for p in out.rglob("*"))
