"""FieldMap: the NetCDF contract, atomic writes, one clear error per defect."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from raysim.errors import FieldMapError
from raysim.maps.fieldmap import fieldmap, grid_of, load, save, validate
from raysim.maps.sphere import SphereGrid, ideal_go_intensity


def small_map(**kw):
    grid = SphereGrid(10.0, 9, 36)
    ideal = np.repeat(ideal_go_intensity(grid.theta, 33.0, 10.0)[:, None], 36, axis=1)
    args = dict(focal_length=33.0, diameter=110.0, frequency_hz=3e8, method="go", sampling="cell_mean",
                scene="name = 'x'\n")
    args.update(kw)
    return grid, fieldmap(grid, ideal * 0.99, ideal, **args)


def test_round_trip_through_plain_xarray(tmp_path: Path):
    grid, ds = small_map(intensity_std=np.full((9, 36), 1e-3))
    path = save(ds, tmp_path / "f.nc")
    with xr.open_dataset(path) as plain:  # any xarray user reads it without raysim
        assert plain["theta"].attrs["units"] == "rad"
        assert plain["intensity"].dims == ("theta", "phi")
        assert plain.attrs["sphere_radius"] == 10.0 and plain.attrs["sampling"] == "cell_mean"
        assert np.array_equal(plain["intensity_ideal"].values, ds["intensity_ideal"].values)
    back = load(path)
    assert grid_of(back) == grid
    assert back.attrs["scene"] == "name = 'x'\n"
    assert "intensity_std" in back


def test_grid_is_rebuilt_from_the_attributes_alone(tmp_path: Path):
    grid = SphereGrid(8.0, 30, 90, np.radians(10), np.radians(70))
    ds = fieldmap(grid, np.ones((30, 90)), np.ones((30, 90)), focal_length=20.0, diameter=40.0,
                  frequency_hz=1e9, method="measured", sampling="centre")
    rebuilt = grid_of(load(save(ds, tmp_path / "m.nc")))
    assert rebuilt.n_theta == 30 and np.isclose(rebuilt.theta_min, np.radians(10))
    assert np.allclose(rebuilt.theta, grid.theta) and np.allclose(rebuilt.cell_area(), grid.cell_area())


def test_write_is_atomic_and_keeps_the_old_file_on_failure(tmp_path: Path, monkeypatch):
    _, ds = small_map()
    path = save(ds, tmp_path / "f.nc")
    before = path.read_bytes()

    def broken(self, *args, **kwargs):
        Path(args[0]).write_bytes(b"half a file")
        raise OSError("disk full")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", broken)
    with pytest.raises(OSError, match="disk full"):
        save(ds, path)
    assert path.read_bytes() == before  # the old map is intact
    assert [p.name for p in tmp_path.iterdir()] == ["f.nc"]  # no temporary left behind


def test_a_full_disk_under_the_netcdf_library_is_an_os_error_naming_the_file(tmp_path: Path,
                                                                             monkeypatch):
    """netCDF4 reports a full disk as RuntimeError("NetCDF: HDF error"), which reached the
    CLI as a 70-line traceback with exit 1: it is an OSError naming the file (one line, exit 2
    in the CLI), the old map intact."""
    import shutil
    from collections import namedtuple

    _, ds = small_map()
    path = save(ds, tmp_path / "f.nc")
    before = path.read_bytes()

    def hdf_error(self, *args, **kwargs):
        Path(args[0]).write_bytes(b"half a file")
        raise RuntimeError("NetCDF: HDF error")

    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(xr.Dataset, "to_netcdf", hdf_error)
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(2**21, 2**21 - 4096, 4096))
    with pytest.raises(OSError, match="no space left on the device") as info:
        save(ds, path)
    assert str(path) in str(info.value)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["f.nc"]


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda ds: ds.drop_vars("intensity_ideal"), "missing variable 'intensity_ideal'"),
        (lambda ds: ds.assign_attrs(sphere_radius=40.0), "sphere_radius must be smaller than focal_length"),
        (lambda ds: ds.drop_attrs(deep=False).assign_attrs(method="go"), "missing attribute 'focal_length'"),
        (lambda ds: ds.assign_coords(theta=ds.theta.assign_attrs(units="deg")), "'theta' must be in rad"),
        (lambda ds: ds.assign_coords(theta=ds.theta * 30), "theta beyond 90 deg"),
        (lambda ds: ds.assign_attrs(focal_length="thirty"), "'focal_length' must be a number"),
        # cut with xarray, the old edges kept: read over them, the data would be stretched
        (lambda ds: ds.isel(theta=slice(0, 5)), "'theta' is not the 5 cell centres between"),
        (lambda ds: ds.isel(phi=slice(0, 9)), "'phi' is not the 9 cell centres between"),
    ],
)
def test_broken_maps_are_refused_with_one_line(tmp_path: Path, damage, message):
    _, ds = small_map()
    bad = damage(ds)
    path = tmp_path / "bad.nc"
    bad.to_netcdf(path)
    with pytest.raises(FieldMapError) as info:
        load(path)
    assert message in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize(("name", "units"), [("intensity", "dB"), ("intensity", "W"),
                                            ("intensity_ideal", "mW"), ("intensity_std", "dBm")])
def test_intensities_not_in_relative_linear_power_are_refused(tmp_path: Path, name, units):
    """The units attribute was never read: a map in dB inverted to nonsense with exit 0, and a
    scan in W was refused for "missing samples". A FieldMap's intensities are |E|^2 relative to
    the incident wave (docs/data.md): units "1", and the message names the unit found."""
    _, ds = small_map(intensity_std=np.full((9, 36), 1e-3))
    ds[name].attrs["units"] = units
    path = tmp_path / "bad.nc"
    ds.to_netcdf(path)
    with pytest.raises(FieldMapError) as info:
        load(path)
    text = str(info.value)
    assert f"'{name}'" in text and repr(units) in text and "'1'" in text and "\n" not in text


@pytest.mark.parametrize("units", ["1", "", None, 1])
def test_dimensionless_intensities_are_read(tmp_path: Path, units):
    """What raysim writes ("1", on every engine's and the rig's maps), an empty unit and none."""
    _, ds = small_map(intensity_std=np.full((9, 36), 1e-3))
    assert ds["intensity"].attrs["units"] == "1" == ds["intensity_ideal"].attrs["units"]
    for name in ("intensity", "intensity_ideal", "intensity_std"):
        if units is None:
            del ds[name].attrs["units"]
        else:
            ds[name].attrs["units"] = units
    path = tmp_path / "ok.nc"
    ds.to_netcdf(path)
    assert np.array_equal(load(path)["intensity"].values, ds["intensity"].values)


def test_unreadable_files_are_field_map_errors(tmp_path: Path):
    junk = tmp_path / "junk.nc"
    junk.write_text("not netcdf")
    with pytest.raises(FieldMapError, match="not a readable NetCDF file"):
        load(junk)
    with pytest.raises(FieldMapError, match="no such file"):
        load(tmp_path / "missing.nc")
    with pytest.raises(FieldMapError, match="is a folder"):
        load(tmp_path)


def test_shape_and_vocabulary_are_checked():
    grid = SphereGrid(10.0, 9, 36)
    with pytest.raises(FieldMapError, match="shape"):
        fieldmap(grid, np.ones((9, 35)), np.ones((9, 36)), focal_length=33, diameter=110, frequency_hz=3e8,
                 method="go", sampling="cell_mean")
    with pytest.raises(FieldMapError, match="method must be one of"):
        small_map(method="magic")


@pytest.mark.parametrize("name", ["intensity", "intensity_ideal", "intensity_std"])
def test_complex_intensities_are_refused_not_cast(tmp_path: Path, name: str):
    # numpy counts complex as a number; a float cast would drop the imaginary part silently
    grid, ds = small_map(intensity_std=np.full((9, 36), 1e-3))
    values = ds[name].values * (1 + 0.5j)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no ComplexWarning on the way to the refusal
        with pytest.raises(FieldMapError, match=f"'{name}' holds complex values: an intensity must be real"):
            validate(ds.assign({name: (("theta", "phi"), values)}))
        with pytest.raises(FieldMapError, match="intensity must be real"):
            save(ds.assign({name: (("theta", "phi"), values)}), tmp_path / "c.nc")
        args = {"intensity": ds["intensity"].values, "intensity_ideal": ds["intensity_ideal"].values,
                "intensity_std": ds["intensity_std"].values, name: values}
        with pytest.raises(FieldMapError, match="intensity must be real"):
            fieldmap(grid, args["intensity"], args["intensity_ideal"], intensity_std=args["intensity_std"],
                     focal_length=33.0, diameter=110.0, frequency_hz=3e8, method="go", sampling="cell_mean")
    assert not (tmp_path / "c.nc").exists()
    # a complex dtype with zero imaginary parts is still not an intensity variable
    with pytest.raises(FieldMapError, match="intensity must be real"):
        validate(ds.assign({name: ds[name].astype(complex)}))


def test_an_ideal_intensity_must_exist_somewhere():
    _, ds = small_map()
    ideal = ds["intensity_ideal"].values
    for none in (np.zeros_like(ideal), np.full_like(ideal, np.nan), np.where(ideal > 0, np.nan, 0.0)):
        with pytest.raises(FieldMapError, match="no ideal intensity") as info:
            validate(ds.assign(intensity_ideal=(("theta", "phi"), none)))
        assert "\n" not in str(info.value)
    # single zero cells are missing samples to the solver, not a broken map
    holes = ideal.copy()
    holes[0, :5] = 0.0
    holes[3, 7] = np.nan
    assert np.array_equal(validate(ds.assign(intensity_ideal=(("theta", "phi"), holes)))["intensity_ideal"].values,
                          holes, equal_nan=True)
    # negative ideal cells were refused before and still are
    with pytest.raises(FieldMapError, match="negative values"):
        validate(ds.assign(intensity_ideal=(("theta", "phi"), -ideal)))


@pytest.mark.parametrize("value", [None, {"a": 1}, True, 1 + 2j, [[1, 2], [3, 4]]])
def test_attributes_netcdf_cannot_store_are_refused_before_writing(tmp_path: Path, value):
    """They failed inside netCDF4 with a TypeError; an existing file stays as it was."""
    _, ds = small_map()
    path = save(ds, tmp_path / "f.nc")
    before = path.read_bytes()
    ds.attrs["note"] = value
    with pytest.raises(FieldMapError, match="attribute 'note' = .* cannot be stored in NetCDF"):
        save(ds, path)
    assert path.read_bytes() == before
    _, ds = small_map()
    ds["intensity"].attrs["note"] = value
    with pytest.raises(FieldMapError, match="attribute intensity: 'note'"):
        save(ds, path)


@pytest.mark.parametrize("value", ["text", 3, 2.5, np.float32(1.5), [1, 2], np.arange(3), np.int64(4)])
def test_attributes_netcdf_stores_are_written_and_read_back(tmp_path: Path, value):
    _, ds = small_map()
    ds.attrs["note"] = value
    back = load(save(ds, tmp_path / "f.nc"))
    assert np.array_equal(np.atleast_1d(back.attrs["note"]), np.atleast_1d(value))


@pytest.mark.parametrize("name", ["polarization", "incidence_theta", "incidence_phi"])
def test_angle_attributes_must_be_finite_numbers(name):
    """'x' reached the refinement's forward model as a float() ValueError."""
    for value in ("x", float("nan")):
        _, ds = small_map()
        ds.attrs[name] = value
        with pytest.raises(FieldMapError, match=f"attribute '{name}' must be a"):
            validate(ds)
