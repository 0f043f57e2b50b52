"""SurfaceMap contract: assembly, NetCDF round trip, and the checks on bad files."""

import numpy as np
import pytest

from solver import surface
from solver.aperture import ApertureGrid
from solver.errors import SurfaceMapError

ATTRS = {"solver": "direct", "boundary": "zero on the rim", "harmonic_part": "unobservable",
         "removed_terms": "none", "focal_length": 33.0, "diameter": 110.0,
         "sphere_radius": 10.0, "harmonic_observable": False}


def test_round_trip_keeps_values_units_and_attributes(tmp_path):
    grid = ApertureGrid(110.0, 32)
    X = grid.XY[0]
    ds = surface.surfacemap(grid, 1e-4 * np.cos(X / 9), ATTRS, truth=1e-4 * np.cos(X / 9.1))
    assert set(ds.data_vars) == {"deformation", "truth", "error"}
    assert np.all(np.isnan(ds["deformation"].values[~grid.mask]))
    path = surface.save(ds, tmp_path / "s.nc")
    back = surface.load(path)
    np.testing.assert_array_equal(back["deformation"].values, ds["deformation"].values)
    np.testing.assert_allclose(back["x"].values, grid.x)
    assert back["error"].attrs["units"] == "m" and back.attrs["harmonic_observable"] == 0
    assert surface.grid_of(back) == grid


def test_bad_files_are_refused_with_one_line(tmp_path):
    grid = ApertureGrid(110.0, 32)
    ds = surface.surfacemap(grid, np.zeros((32, 32)), ATTRS)
    with pytest.raises(SurfaceMapError, match="no such file"):
        surface.load(tmp_path / "none.nc")
    (tmp_path / "junk.nc").write_text("not netcdf")
    with pytest.raises(SurfaceMapError, match="not a readable"):
        surface.load(tmp_path / "junk.nc")
    bad = ds.copy(deep=True)
    bad["deformation"].attrs["units"] = "mm"
    with pytest.raises(SurfaceMapError, match="must be in m"):
        surface.validate(bad)
    with pytest.raises(SurfaceMapError, match="missing attribute 'boundary'"):
        surface.validate(ds.assign_attrs(boundary=None).drop_attrs(deep=False)
                         .assign_attrs({k: v for k, v in ds.attrs.items() if k != "boundary"}))
    with pytest.raises(SurfaceMapError, match="missing variable"):
        surface.validate(ds.drop_vars("deformation"))
