"""Inputs stored in any legal order give the canonical answer; NetCDF files get the umask's
mode; the ideal GO cell mean is zero beyond the rim image."""

from __future__ import annotations

import os
import stat

import numpy as np
import pytest

from raysim.errors import FieldMapError
from raysim.maps.fieldmap import load, save
from raysim.maps.sphere import SphereGrid, ideal_go_cell_mean, theta_rim
from raysim.surface.deformation import GaussianBumps
from raysim.surface.mapfile import read_map
from solver.run import run_invert
from tests.examples import equation_fieldmap

BUMP = GaussianBumps(((10.0, 5.0, 200e-6, 6.0), (-20.0, -12.0, -150e-6, 8.0)))


@pytest.fixture(scope="module")
def canonical(tmp_path_factory):
    folder = tmp_path_factory.mktemp("canonical")
    field = equation_fieldmap(BUMP, n_theta=45, n_phi=90)
    path = save(field, folder / "field.nc")
    surface = run_invert(path, folder / "surface.nc", N=64, refine=1)
    return folder, field, surface


@pytest.mark.parametrize("order", ["theta descending", "phi descending", "both descending",
                                   "dims (phi, theta)", "all at once"])
def test_any_legal_order_inverts_to_the_canonical_answer(canonical, order):
    folder, field, surface = canonical
    ds = field
    if "theta" in order or "both" in order or "all" in order:
        ds = ds.isel(theta=slice(None, None, -1))
    if "phi desc" in order or "both" in order or "all" in order:
        ds = ds.isel(phi=slice(None, None, -1))
    if "dims" in order or "all" in order:
        ds = ds.transpose("phi", "theta")
    path = folder / f"{order.replace(' ', '_')}.nc"
    ds.to_netcdf(path)  # stored as given, not through save()
    back = load(path)
    assert back["intensity"].dims == ("theta", "phi")
    np.testing.assert_array_equal(back["intensity"].values, field["intensity"].values)
    result = run_invert(path, folder / f"{order}_surface.nc", N=64, refine=1)
    np.testing.assert_array_equal(result["deformation"].values, surface["deformation"].values)
    assert result.attrs["samples_missing"] == surface.attrs["samples_missing"] == 0


def test_a_map_file_in_any_order_reads_as_the_canonical_one(tmp_path):
    import xarray as xr

    x = np.linspace(-60.0, 60.0, 25)
    y = np.linspace(-60.0, 60.0, 21)
    X, Y = np.meshgrid(x, y, indexing="xy")
    dz = 1e-4 * np.cos(X / 20.0) * np.sin(Y / 15.0)
    ds = xr.Dataset({"deformation": (("y", "x"), dz, {"units": "m"})}, coords={"x": x, "y": y})
    ds.to_netcdf(tmp_path / "a.nc")
    ds.isel(x=slice(None, None, -1), y=slice(None, None, -1)).transpose("x", "y").to_netcdf(tmp_path / "b.nc")
    a, b = read_map(tmp_path / "a.nc"), read_map(tmp_path / "b.nc")
    px, py = np.array([3.0, -17.5, 40.2]), np.array([-8.0, 22.1, 5.0])
    np.testing.assert_array_equal(a(px, py), b(px, py))


def test_a_coordinate_that_repeats_or_zigzags_is_refused(canonical, tmp_path):
    _, field, _ = canonical
    theta = field["theta"].values.copy()
    theta[[3, 4]] = theta[[4, 3]]
    field.assign_coords(theta=theta).to_netcdf(tmp_path / "zigzag.nc")
    with pytest.raises(FieldMapError, match="strictly monotonic"):
        load(tmp_path / "zigzag.nc")


def test_netcdf_files_get_the_mode_of_any_new_file(canonical, tmp_path):
    _, field, _ = canonical
    old = os.umask(0o022)
    try:
        path = save(field, tmp_path / "f.nc")
        assert stat.S_IMODE(path.stat().st_mode) == 0o644
        os.umask(0o027)
        path = save(field, tmp_path / "g.nc")
        assert stat.S_IMODE(path.stat().st_mode) == 0o640
    finally:
        os.umask(old)


def test_ideal_cell_mean_holds_no_power_beyond_the_rim_image():
    F, R, D = 33.0, 10.0, 110.0
    grid = SphereGrid(R, 90, 360)
    e = grid.theta_edges
    mean = ideal_go_cell_mean(e[:-1], e[1:], F, R, D)
    rim = theta_rim(D, F)
    beyond = e[:-1] >= rim
    assert beyond.any() and np.all(mean[beyond] == 0.0)
    # the cell the rim cuts holds the power of its lit part only (numerical quadrature of the
    # point law (rho/R)^2 over the lit band, divided by the whole band's solid angle)
    from scipy.integrate import quad

    k = int(np.searchsorted(e, rim)) - 1
    lit, _ = quad(lambda t: (2 * F / (R * (1 + np.cos(t)))) ** 2 * np.sin(t), e[k], rim)
    assert mean[k] == pytest.approx(lit / (np.cos(e[k]) - np.cos(e[k + 1])), rel=1e-10)
