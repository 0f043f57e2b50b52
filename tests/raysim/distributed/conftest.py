"""Shared pieces of the distributed tests: a small dish, an in-process cluster, comparisons."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from raysim.distributed.simulate import RUN_ATTRS

# a 10 m dish at 1 GHz (33 wavelengths across), probe sphere of 2 m: 324 points, ~8000 PO samples
SMALL = """
name = "small"
method = "po"
[dish]
diameter_m = 10.0
focal_length_m = 4.0
resolution_m = 1.0
[[deformation]]
type = "paper"
scale = 1.0
[source]
frequency_hz = 1.0e9
[sphere]
radius_m = 2.0
n_theta = 9
n_phi = 36
"""


@pytest.fixture(scope="module")
def inproc():
    """A Dask cluster of two single-thread workers inside this process (no network).

    The job plugin sets RAYSIM_THREADS in its worker's process, here ours: it is restored.
    """
    from distributed import LocalCluster

    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("RAYSIM_THREADS", "1")
        with LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                          dashboard_address=":0") as cluster:
            yield cluster.scheduler_address


def assert_same_fieldmap(a: xr.Dataset, b: xr.Dataset) -> None:
    """Every variable and coordinate bit for bit, every attribute but the run's figures."""
    assert sorted(a.data_vars) == sorted(b.data_vars)
    for name in list(a.data_vars) + list(a.coords):
        assert a[name].dtype == b[name].dtype, name
        assert np.array_equal(a[name].values, b[name].values, equal_nan=a[name].dtype.kind == "f"), name
    def kept(attrs: dict) -> dict:
        # a NaN attribute (a mesh's resolution) is equal to itself here
        return {k: "nan" if isinstance(v, float) and v != v else v
                for k, v in attrs.items() if k not in RUN_ATTRS}

    assert kept(a.attrs) == kept(b.attrs)
