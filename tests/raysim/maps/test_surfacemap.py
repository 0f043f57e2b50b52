"""SurfaceMap (raysim.maps.surfacemap): values that are not real lengths are refused in one line.

The round trip and the other contract checks are in tests/solver/test_surface.py (the solver
re-exports the module).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from raysim.errors import SurfaceMapError
from raysim.maps.aperture import ApertureGrid
from raysim.maps.surfacemap import surfacemap, validate

ATTRS = {"solver": "direct", "boundary": "zero on the rim", "harmonic_part": "unobservable",
         "removed_terms": "none", "focal_length": 33.0, "diameter": 110.0, "sphere_radius": 10.0}
GRID = ApertureGrid(110.0, 16)


def small_map():
    X, Y = GRID.XY
    return surfacemap(GRID, 1e-4 * np.cos(X / 9), ATTRS, truth=1e-4 * np.cos(Y / 9),
                      deformation_std=np.full((16, 16), 1e-6))


@pytest.mark.parametrize("name", ["deformation", "truth", "error", "deformation_std"])
def test_complex_and_text_values_are_refused(name: str):
    ds = small_map()
    dims = ("y", "x")
    attrs = ds[name].attrs
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no ComplexWarning: refused, not cast
        with pytest.raises(SurfaceMapError, match=f"'{name}' holds complex values: a deformation must be real"):
            validate(ds.assign({name: (dims, ds[name].values * (1 + 1j), attrs)}))
    text = np.full((16, 16), "0.1", dtype=object).astype(str)
    with pytest.raises(SurfaceMapError, match=f"'{name}' must hold numbers") as info:
        validate(ds.assign({name: (dims, text, attrs)}))
    assert "\n" not in str(info.value)


def test_the_constructor_refuses_them_too():
    X, _ = GRID.XY
    good = 1e-4 * np.cos(X / 9)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(SurfaceMapError, match="'deformation' holds complex values"):
            surfacemap(GRID, good + 1e-5j, ATTRS)
        with pytest.raises(SurfaceMapError, match="'truth' holds complex values"):
            surfacemap(GRID, good, ATTRS, truth=good.astype(complex))
    with pytest.raises(SurfaceMapError, match="'deformation' must hold numbers"):
        surfacemap(GRID, np.full((16, 16), "abc"), ATTRS)
    with pytest.raises(SurfaceMapError, match="'deformation' must hold numbers"):
        surfacemap(GRID, np.full((16, 16), "abc"), ATTRS, truth=good)
    # a real map still passes, its values kept exactly inside the aperture
    ds = surfacemap(GRID, good, ATTRS)
    assert np.array_equal(ds["deformation"].values[GRID.mask], good[GRID.mask])
