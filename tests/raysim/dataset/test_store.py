"""The dataset's Zarr store without a cluster: layout, units, markers, refusals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import zarr

from raysim.dataset import DatasetError, load_spec, open_dataset, sample_seed, validation_mask
from raysim.dataset import store as zstore

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def spec():
    return load_spec(ROOT / "scenes" / "dataset_demo.toml")


def test_new_store_layout(spec, tmp_path):
    path = str(tmp_path / "new.zarr")
    group = zstore.create(path, spec)
    assert [p.name for p in tmp_path.iterdir()] == ["new.zarr"]  # no scratch folder left
    n, sphere = spec.samples, spec.scene.sphere
    assert group["intensity"].shape == (n, sphere.n_theta, sphere.n_phi)
    assert group["intensity"].chunks == (1, sphere.n_theta, sphere.n_phi)  # one sample per chunk
    assert group["deformation"].shape == (n, spec.grid_n, spec.grid_n)
    assert group["panel_rigid_piston"].shape == (n, spec.scene.panels.n_panels)
    for name, arr in group.arrays():
        assert "units" in arr.attrs, name
        if arr.metadata.dimension_names[0] == "sample" and name not in ("sample", "seed", "split"):
            assert arr.chunks[0] == 1, name  # workers never share a chunk
    assert np.array_equal(group["seed"][...], [sample_seed(spec.seed, i) for i in range(n)])
    assert np.array_equal(group["split"][...], validation_mask(spec))
    assert (zstore.status(group) == zstore.PENDING).all()
    ds = open_dataset(path)
    assert ds["intensity"].dims == ("sample", "theta", "phi")
    assert ds["deformation"].dims == ("sample", "y", "x")
    assert np.allclose(ds["theta"].values, sphere.theta) and ds.attrs["fingerprint"] == spec.fingerprint
    assert ds.attrs["method"] == "go" and ds.attrs["sampling"] == "cell_mean"
    assert ds.attrs["version_zarr"] == zarr.__version__ and spec.text == ds.attrs["spec"]


def test_a_torn_marker_counts_as_pending(spec, tmp_path):
    path = str(tmp_path / "torn.zarr")
    group = zstore.create(path, spec)
    writer = zstore.Writer(group)
    writer.failed(1, "a reason\nover two lines")
    group["status"][3] = zstore.DONE
    (tmp_path / "torn.zarr" / "status" / "c" / "3").write_bytes(b"\x00\x01garbage")
    status = zstore.status(zarr.open_group(path, mode="r"))
    assert status.tolist() == [0, 2, 0, 0, 0, 0, 0, 0]
    assert group["error"][1] == "a reason over two lines"


def test_foreign_stores_are_refused(spec, tmp_path):
    foreign = tmp_path / "foreign.zarr"
    zarr.open_group(str(foreign), mode="w").create_array("a", shape=(2,), dtype="f8")
    with pytest.raises(DatasetError, match="not a raysim dataset"):
        zstore.open_checked(str(foreign), spec)
    (tmp_path / "plain").mkdir()
    with pytest.raises(DatasetError):
        zstore.open_checked(str(tmp_path / "plain"), spec)
