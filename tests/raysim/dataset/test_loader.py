"""Loaders: a store with measurement effects read back batch by batch, through every
representation, at fsspec URLs and through the PyTorch wrapper where PyTorch is installed."""

from __future__ import annotations

import fsspec
import numpy as np
import pytest
import zarr

from raysim.dataset import DatasetError
from raysim.dataset.loader import REPRESENTATIONS, Loader

pytestmark = pytest.mark.slow  # they read a store made by a local Dask cluster


@pytest.fixture()
def store(measured_store, tmp_path):
    """A private copy of the measured store (the loaders write statistics into it), one of
    its training samples marked pending as if it had not run yet."""
    import shutil

    _, path = measured_store
    copy = tmp_path / "copy.zarr"
    shutil.copytree(path, copy)
    group = zarr.open_group(str(copy), mode="r+")
    split = group["split"][...]
    pending = int(np.flatnonzero(split == 0)[0])
    group["status"][pending] = 0
    return copy, pending


def _arrays(path):
    group = zarr.open_group(str(path), mode="r")
    return {name: np.asarray(group[name][...]) for name in
            ("intensity", "intensity_measured", "intensity_ideal", "deformation", "split", "status")}


@pytest.mark.parametrize("source", ["clean", "measured"])
def test_batches_are_the_stored_arrays_of_the_split(store, source):
    path, pending = store
    a = _arrays(path)
    stored = a["intensity" if source == "clean" else "intensity_measured"]
    for split, flag in (("train", 0), ("validation", 1)):
        loader = Loader(str(path), source=source, split=split, batch_size=2, shuffle=True, seed=5,
                        normalise=False, fill=np.nan, dtype="float64")
        expected = np.flatnonzero((a["split"] == flag) & (a["status"] == 1))
        assert pending not in loader.indices and np.array_equal(loader.indices, expected)
        for epoch in range(2):
            seen = []
            for x, y in loader:
                index = [next(i for i in range(len(stored))
                              if np.array_equal(a["deformation"][i], yi, equal_nan=True)) for yi in y]
                for xi, i in zip(x, index, strict=True):
                    assert np.array_equal(xi, stored[i], equal_nan=True)
                seen += index
            assert sorted(seen) == expected.tolist()
            if epoch == 0:
                first = seen
        assert len(expected) < 3 or first != seen  # a new order each epoch


def test_representations_follow_their_definitions(store):
    path, _ = store
    a = _arrays(path)
    loader = Loader(str(path), representation="fa_sphere", split="all", normalise=False, fill=np.nan,
                    dtype="float64")
    x, _ = loader.raw(loader.indices)
    ideal = a["intensity_ideal"][0]
    for xi, i in zip(x, loader.indices, strict=True):
        lit = (ideal > 0) & (a["intensity"][i] > 0)
        assert np.allclose(xi[lit], ideal[lit] / a["intensity"][i][lit] - 1.0, rtol=1e-14, atol=0)
        assert np.isnan(xi[~lit]).all()
    aperture = Loader(str(path), representation="fa_aperture", split="all", normalise=False)
    xa, ya = aperture.raw(aperture.indices[:2])
    mask = aperture.target_mask
    assert xa.shape == ya.shape == (2, *mask.shape)
    assert np.isfinite(xa[:, mask]).all() and np.isnan(xa[:, ~mask]).all()
    # FA on the aperture is the sphere's FA carried along r = 2F tan(theta / 2): compare means
    # over matching annuli (theta < 60 deg)
    F = float(zarr.open_group(str(path)).attrs["focal_length"])
    x_coord = np.asarray(zarr.open_group(str(path))["x"][...])
    X, Y = np.meshgrid(x_coord, x_coord)
    theta_of_point = 2.0 * np.arctan(np.hypot(X, Y) / (2.0 * F))
    theta = np.asarray(zarr.open_group(str(path))["theta"][...])
    band = (theta_of_point > np.radians(20)) & (theta_of_point < np.radians(60)) & mask
    rows = (theta > np.radians(20)) & (theta < np.radians(60))
    for k in range(2):
        assert np.mean(xa[k][band]) == pytest.approx(np.nanmean(x[k][rows]), abs=0.2 * np.nanstd(x[k][rows]))


@pytest.mark.parametrize("representation", REPRESENTATIONS)
def test_statistics_are_the_training_split_and_kept_in_the_store(store, representation, monkeypatch):
    path, _ = store
    loader = Loader(str(path), representation=representation, source="measured", split="validation",
                    batch_size=4)
    train = Loader(str(path), representation=representation, source="measured", split="train",
                   normalise=False)
    x, y = train.raw(train.indices)
    s = loader.statistics
    assert s.samples == len(train.indices)
    assert s.input_mean == pytest.approx(np.nanmean(x), rel=1e-10)
    assert s.input_std == pytest.approx(np.nanstd(x), rel=1e-10)
    assert s.target_mean == pytest.approx(np.nanmean(y), rel=1e-10, abs=1e-18)
    assert s.target_std == pytest.approx(np.nanstd(y), rel=1e-10)
    kept = zarr.open_group(str(path)).attrs["normalisation"][loader.key]
    assert kept["input_std"] == s.input_std
    # a second loader reads them back without touching a sample
    monkeypatch.setattr(Loader, "raw", lambda self, indices: pytest.fail("statistics recomputed"))
    assert Loader(str(path), representation=representation, source="measured").statistics == s


def test_normalised_batches_undo_to_the_store(store):
    path, _ = store
    a = _arrays(path)
    loader = Loader(str(path), source="measured", batch_size=3, dtype="float64")
    s = loader.statistics
    x, y = next(iter(loader))
    first = loader.indices[:3]
    measured = a["intensity_measured"][first]
    finite = np.isfinite(measured)
    assert np.allclose(x[finite] * s.input_std + s.input_mean, measured[finite], rtol=1e-12)
    assert np.all(x[~finite] == 0.0)  # missing points filled
    inside = loader.target_mask
    assert np.allclose(y[:, inside] * s.target_std + s.target_mean, a["deformation"][first][:, inside],
                       rtol=1e-9, atol=1e-15)


def test_stores_at_fsspec_urls_read_the_same(store):
    path, _ = store
    local = list(Loader(str(path), split="all", batch_size=4))
    fs = fsspec.filesystem("memory")
    fs.put(str(path), "/loader-test.zarr", recursive=True)
    try:
        for url in (f"file://{path}", "memory://loader-test.zarr"):
            remote = list(Loader(url, split="all", batch_size=4))
            assert len(remote) == len(local)
            for (x0, y0), (x1, y1) in zip(local, remote, strict=True):
                assert np.array_equal(x0, x1) and np.array_equal(y0, y1)
    finally:
        fs.rm("/loader-test.zarr", recursive=True)


def test_bad_loader_options_are_one_clear_error(store):
    path, _ = store
    with pytest.raises(DatasetError, match="unknown representation"):
        Loader(str(path), representation="phase")
    with pytest.raises(DatasetError, match="unknown split"):
        Loader(str(path), split="test")
    # each of these became a TypeError, or was quietly truncated or replaced (grid_n 0)
    for bad, says in (({"grid_n": 0}, "grid_n must be an integer >= 8"),
                      ({"grid_n": 48.7}, "grid_n must be an integer"),
                      ({"batch_size": "2"}, "batch_size must be an integer"),
                      ({"seed": -1}, "seed must be an integer >= 0"),
                      ({"fill": "x"}, "fill must be a number"),
                      ({"dtype": "foo"}, "dtype must name a floating-point type"),
                      ({"dtype": "int32"}, "dtype must name a floating-point type")):
        with pytest.raises(DatasetError, match=says):
            Loader(str(path), **bad)


def test_pytorch_dataset_round_trip(store):
    torch = pytest.importorskip("torch")
    from raysim.dataset.torch_data import TorchDataset

    path, _ = store
    data = TorchDataset(str(path), representation="fa_sphere", source="measured", split="train")
    loader = Loader(str(path), representation="fa_sphere", source="measured", split="train",
                    batch_size=2)
    assert len(data) == len(loader.indices)
    batches = torch.utils.data.DataLoader(data, batch_size=2, shuffle=False)
    for (x, y), (u, v) in zip(batches, loader, strict=True):
        assert x.dtype == torch.float32 and np.array_equal(x.numpy(), u) and np.array_equal(y.numpy(), v)
    assert data.target_mask.dtype == torch.bool


def test_jax_batches_round_trip(store):
    pytest.importorskip("jax")
    from raysim.dataset.jax_data import jax_batches

    path, _ = store
    loader = Loader(str(path), split="all", batch_size=2)
    reference = list(Loader(str(path), split="all", batch_size=2))
    for (x, y), (u, v) in zip(jax_batches(loader), reference, strict=True):
        assert np.array_equal(np.asarray(x), u) and np.array_equal(np.asarray(y), v)


def test_a_torn_status_chunk_counts_its_samples_as_not_done(store):
    """A status chunk cut short (a kill mid-write) raised zarr's raw decoder RuntimeError from
    the Loader; the samples it holds are now left out, as the writer's resume treats them."""
    path, pending = store
    chunks = sorted(f for f in (path / "status" / "c").rglob("*") if f.is_file())
    torn = chunks[-1]
    torn.write_bytes(b"")
    every = np.asarray(zarr.open_group(str(path), mode="r")["split"][...])
    loader = Loader(path, split="all")
    kept = set(loader.indices.tolist())
    assert pending not in kept and 0 < len(kept) < every.size


def _edit_mean(entry, path):
    entry["input_mean"] = 1000.0  # a hand edit: the digest alone still matches the old key


def _malformed(entry, path):
    for key in ("input_std", "target_mean", "target_std"):
        del entry[key]  # partly written


def _other_data(entry, path):
    """A training sample's data changed (and its checksum with it, as a rerun would): the kept
    entry was made from the old data under the same indices."""
    from raysim.dataset import store as zstore

    group = zarr.open_group(str(path), mode="r+")
    done = np.asarray(group["status"][...]) == 1
    index = int(np.flatnonzero(done & (np.asarray(group["split"][...]) == 0))[0])
    group["intensity_measured"][index] = np.asarray(group["intensity_measured"][index]) * 3.0
    group["checksum"][index] = zstore.sample_checksum(group, index)


@pytest.mark.parametrize("change", [_edit_mean, _malformed, _other_data])
def test_a_kept_normalisation_that_is_not_current_is_computed_again(store, change):
    path, _ = store
    assert Loader(str(path), source="measured").statistics.samples > 0  # kept in the store
    group = zarr.open_group(str(path), mode="r+")
    kept = dict(group.attrs["normalisation"])
    entry = dict(kept["intensity/measured"])
    change(entry, path)
    kept["intensity/measured"] = entry
    group.attrs["normalisation"] = kept
    train = Loader(str(path), source="measured", normalise=False)
    x, y = train.raw(train.indices)
    s = Loader(str(path), source="measured").statistics
    assert s.input_mean == pytest.approx(np.nanmean(x), rel=1e-10)
    assert s.input_std == pytest.approx(np.nanstd(x), rel=1e-10)
    assert s.target_std == pytest.approx(np.nanstd(y), rel=1e-10)
    assert s.samples == len(train.indices)


def test_a_lost_measured_intensity_is_named_not_blamed_on_the_spec(store):
    """The store was made with [measurement]: its intensity_measured losing its metadata is
    damage to repair, not a spec without measurement effects."""
    from raysim.dataset import open_dataset
    from raysim.dataset.integrity import CorruptStoreError

    path, _ = store
    (path / "intensity_measured" / "zarr.json").unlink()
    for read in (lambda: Loader(str(path), source="measured"), lambda: open_dataset(path)):
        with pytest.raises(CorruptStoreError, match="'intensity_measured' is missing") as info:
            read()
        assert "[measurement]" not in str(info.value) and "--resume" in str(info.value)
