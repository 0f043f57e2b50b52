"""Reading a dataset back: the whole store as a lazy xarray Dataset, one sample as a FieldMap,
and any sample regenerated alone from its spec (no store, no cluster)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

from raysim.dataset.sampling import draw_sample
from raysim.dataset.spec import DatasetSpec
from raysim.dataset.store import open_readonly


def open_dataset(store: str | Path) -> xr.Dataset:
    """The store as an ``xarray.Dataset`` backed by lazy Dask arrays (nothing is loaded).

    Use only samples with ``status == 1``; ``split == 1`` marks the validation samples.
    """
    open_readonly(str(store))  # one clear line if it is not a raysim dataset
    ds = xr.open_zarr(str(store), consolidated=False)
    names = [v for v in ds.data_vars if v.endswith(("_term_n", "_term_m"))]
    return ds.set_coords(names)


def sample_fieldmap(ds: xr.Dataset, index: int) -> xr.Dataset:
    """Sample ``index`` of an opened dataset as a FieldMap (see :mod:`raysim.maps.fieldmap`)."""
    from raysim.maps.fieldmap import fieldmap, grid_of

    sample = ds.isel(sample=index)
    frequency = float(sample["frequency_hz"].values)
    ideal = ds["intensity_ideal"].sel(frequency=frequency)
    attrs = {"dataset": ds.attrs.get("name", ""), "sample": int(index),
             "seed": str(int(sample["seed"].values)), "deformation_rms": float(sample["rms"].values)}
    return fieldmap(grid_of(ds), sample["intensity"].values, ideal.values,
                    focal_length=ds.attrs["focal_length"], diameter=ds.attrs["diameter"],
                    frequency_hz=frequency, method=ds.attrs["method"], sampling=ds.attrs["sampling"],
                    scene=ds.attrs.get("scene"), attrs=attrs)


def sample_intensity(spec: DatasetSpec, index: int, device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
    """Regenerate sample ``index`` alone, in this process: (deformation map (m), intensity)."""
    from raysim.dataset.engine import simulate_sample

    draw = draw_sample(spec, index)
    return spec.grid.evaluate(draw.deformation), simulate_sample(spec, draw.deformation,
                                                                  draw.frequency_index, device)
