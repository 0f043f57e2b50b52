"""A store damaged outside its samples, or read back damaged: what a resume rewrites, what it
refuses, what the readers refuse, and what killed runs leave beside a store.

Every check compares with a clean store made once, uninterrupted (the independent reference):
a repaired store must be that store again, a refused one byte-identical to what it was.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import zarr

from raysim.dataset import DatasetError, Loader, generate, open_dataset, parse_spec, sample_fieldmap
from raysim.dataset import store as zstore
from raysim.dataset.integrity import STATIC_ATTR, CorruptSampleError, CorruptStoreError
from raysim.files import writer_prefix
from tests.cli import run_cli
from tests.raysim.dataset.conftest import ROOT, small_demo_text

pytestmark = pytest.mark.slow  # a store made by an in-process Dask cluster
PROVENANCE = {"seconds", "cpu_seconds", "finished"}  # when and how long: differ between runs


@pytest.fixture(scope="module")
def spec():
    return parse_spec(small_demo_text(samples=4, measurement=False), source="small4.toml",
                      base=ROOT / "scenes")


@pytest.fixture(scope="module")
def clean(tmp_path_factory, spec, inproc):
    """The reference: the small dataset made once, uninterrupted."""
    path = tmp_path_factory.mktemp("clean") / "small.zarr"
    report = generate(spec, path, scheduler=inproc)
    assert report.done == spec.samples and not report.rewritten and not report.repaired
    return path


@pytest.fixture()
def copy(clean, tmp_path):
    path = tmp_path / "copy.zarr"
    shutil.copytree(clean, path)
    return path


def _files(path: Path) -> dict[str, bytes]:
    return {str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()}


def assert_same_store(a: Path, b: Path) -> None:
    """Every array bit-identical (NaN where NaN) but the run's timings, the same attributes
    but the creation date."""
    left, right = (zarr.open_group(str(p), mode="r") for p in (a, b))
    names = sorted(n for n, _ in left.arrays())
    assert names == sorted(n for n, _ in right.arrays())
    for name in set(names) - PROVENANCE:
        x, y = np.asarray(left[name][...]), np.asarray(right[name][...])
        same = np.array_equal(x, y, equal_nan=True) if x.dtype.kind == "f" else np.array_equal(x, y)
        assert same, f"array {name!r} differs"
    attrs = [dict(g.attrs) for g in (left, right)]
    for d in attrs:
        d.pop("created")
    assert attrs[0] == attrs[1]


# --- A: creation-time arrays and attributes -----------------------------------------------------------
def _remove(name: str):
    def damage(path: Path) -> None:
        (path / name / "c" / "0").unlink()
    return damage


def _edit_diameter(path: Path) -> None:
    root = path / "zarr.json"
    text = root.read_text()
    assert '"diameter": 110.0' in text
    root.write_text(text.replace('"diameter": 110.0', '"diameter": 90.0'))


@pytest.mark.parametrize(("damage", "rewritten"), [
    (_remove("split"), "split"), (_remove("seed"), "seed"), (_remove("theta"), "theta"),
    (_remove("frequency"), "frequency"), (_remove("x"), "x"), (_edit_diameter, "attribute diameter")])
def test_a_resume_rewrites_what_the_spec_gives_and_readers_refuse_it_until_then(
        clean, copy, spec, inproc, damage, rewritten):
    damage(copy)
    what = rewritten.removeprefix("attribute ")
    for read in (lambda: Loader(str(copy), split="all"), lambda: open_dataset(copy)):
        with pytest.raises(CorruptStoreError, match="--resume") as info:
            read()
        assert str(copy) in str(info.value) and what in str(info.value)
    report = generate(spec, copy, resume=True, scheduler=inproc)
    assert report.rewritten == (rewritten,) and report.computed == 0 and report.repaired == 0
    assert f"rewritten from it: {rewritten}" in report.summary()
    assert_same_store(clean, copy)  # the split, seeds, coordinates and attributes made again
    validation = np.flatnonzero(zarr.open_group(str(clean), mode="r")["split"][...] == 1)
    assert len(validation) == 2  # the spec's round(0.5 * 4)
    assert np.array_equal(Loader(str(copy), split="validation").indices, validation)


# --- B: missing or unreadable array metadata ----------------------------------------------------------
def _garble(name: str):
    def damage(path: Path) -> None:
        (path / name).write_text("{not json")
    return damage


def _unlink(name: str):
    def damage(path: Path) -> None:
        target = path / name
        shutil.rmtree(target) if target.is_dir() else target.unlink()
    return damage


def _truncate(name: str, size: int = 50):
    def damage(path: Path) -> None:
        target = path / name
        target.write_bytes(target.read_bytes()[:size])
    return damage


def _codecs_lost(name: str):
    """The compression codec dropped from the array's zarr.json (its chunks still compressed):
    the metadata read, every chunk read as garbage, and the resume recomputed every sample and
    wrote it uncompressed, leaving the metadata as it found it."""
    def damage(path: Path) -> None:
        meta = path / name / "zarr.json"
        data = json.loads(meta.read_text())
        data["codecs"] = [c for c in data["codecs"] if c["name"] == "bytes"]
        meta.write_text(json.dumps(data))
    return damage


def _fill_changed(name: str, fill):
    """The array's fill value changed in its zarr.json (0.0 for NaN: a lost chunk would read as
    zeros); the readers accepted it."""
    def damage(path: Path) -> None:
        meta = path / name / "zarr.json"
        data = json.loads(meta.read_text())
        data["fill_value"] = fill
        meta.write_text(json.dumps(data))
    return damage


@pytest.mark.parametrize(("damage", "array", "computed"), [
    (_codecs_lost("intensity"), "intensity", 0), (_fill_changed("intensity", 0.0), "intensity", 0),
    (_fill_changed("status", 1), "status", 0),
    (_unlink("intensity/zarr.json"), "intensity", 0), (_unlink("status/zarr.json"), "status", 0),
    (_truncate("deformation/zarr.json"), "deformation", 0), (_garble("checksum/zarr.json"), "checksum", 0),
    (_unlink("split/zarr.json"), "split", 0), (_unlink("ideal_status/zarr.json"), "ideal_status", 0),
    (_unlink("gravity_rms"), "gravity_rms", 4)])
def test_a_resume_restores_lost_array_metadata_from_the_layout(clean, copy, spec, inproc, damage, array,
                                                               computed):
    """An array's ``zarr.json`` lost (removed, truncated, garbled, its codecs changed): the
    readers say to resume,
    and the resume writes it again as the layout makes it, keeping the chunks, which verify,
    so no sample is lost; an array removed whole reads as its fill value, and the samples it
    held fail their checksums and are recomputed. The store is then the clean one bit for bit."""
    damage(copy)
    for read in (lambda: Loader(str(copy), split="all"), lambda: open_dataset(copy)):
        with pytest.raises(CorruptStoreError, match="--resume") as info:
            read()
        assert str(copy) in str(info.value) and f"'{array}'" in str(info.value)
    report = generate(spec, copy, resume=True, scheduler=inproc)
    assert f"{array} metadata" in report.rewritten and f"{array} metadata" in report.summary()
    assert (report.computed, report.repaired) == (computed, computed)
    assert_same_store(clean, copy)
    assert _files(copy)[f"{array}/zarr.json"] == _files(clean)[f"{array}/zarr.json"]
    loader = Loader(str(copy), split="all")
    assert len(loader.indices) == spec.samples and sum(x.shape[0] for x, _ in loader) == spec.samples


def test_a_resume_refuses_an_array_of_another_shape_and_touches_nothing(copy, spec, inproc):
    """An array whose metadata reads but is not the layout's is no array this spec made: refused."""
    meta = copy / "rms" / "zarr.json"
    data = json.loads(meta.read_text())
    data["shape"] = [spec.samples + 1]
    meta.write_text(json.dumps(data))
    before = _files(copy)
    with pytest.raises(DatasetError, match="its array 'rms' does not have the shape") as info:
        generate(spec, copy, resume=True, scheduler=inproc)
    assert str(copy) in str(info.value) and "\n" not in str(info.value)
    assert _files(copy) == before


def test_the_cli_resume_restores_a_lost_array_metadata(clean, copy, spec, tmp_path):
    source = tmp_path / "small4.toml"
    source.write_text(spec.text)  # its scene is inline: the same spec from any folder
    (copy / "intensity" / "zarr.json").unlink()
    result = run_cli("dataset", str(source), "-o", str(copy), "--resume", timeout=120)
    assert result.returncode == 0 and "intensity metadata" in result.stdout + result.stderr, result.stderr
    assert _files(copy)["intensity/zarr.json"] == _files(clean)["intensity/zarr.json"]
    good = {k: v for k, v in _files(clean).items() if k.startswith("intensity/")}
    assert {k: v for k, v in _files(copy).items() if k.startswith("intensity/")} == good  # none recomputed


# --- B2: unreadable bookkeeping chunks ----------------------------------------------------------------
def _chunk(path: Path, name: str, index: int) -> Path:
    target = path / name / "c" / str(index)
    target.parent.mkdir(parents=True, exist_ok=True)
    return target


@pytest.mark.parametrize(("name", "index"), [("ideal_status", 0), ("status", 3), ("checksum", 1)])
def test_a_garbled_marker_or_checksum_is_recomputed_and_counted(clean, copy, spec, inproc, name, index):
    """Two junk bytes over a completion marker or a checksum: the readers say to resume (a
    sample whose marker is unreadable reads as pending, which readers leave out), the resume
    recomputes that one item (it refused the store over an ideal's marker), says "1 done item
    ... was", and the store is the clean one bit for bit."""
    _chunk(copy, name, index).write_bytes(b"zz")
    if name != "status":
        with pytest.raises(CorruptSampleError, match="--resume"):
            list(Loader(str(copy), representation="fa_sphere", split="all"))
    report = generate(spec, copy, resume=True, scheduler=inproc)
    assert report.repaired == 1 and report.computed == (0 if name == "ideal_status" else 1)
    assert "; 1 done item failed verification and was recomputed" in report.summary()
    assert "nothing left to compute" not in report.summary()
    assert_same_store(clean, copy)


@pytest.mark.parametrize("name", ["ideal_status", "status"])
def test_a_removed_marker_of_a_finished_item_is_recomputed_and_counted(clean, copy, spec, inproc, name):
    """A done item's marker chunk removed (it reads as pending, its checksum is there): the
    summary counts it, not "nothing left to compute"."""
    _chunk(copy, name, 0).unlink()
    report = generate(spec, copy, resume=True, scheduler=inproc)
    assert report.repaired == 1 and "1 done item failed verification and was recomputed" in report.summary()
    assert_same_store(clean, copy)


@pytest.mark.parametrize(("name", "index", "fill"), [
    ("seconds", 3, np.nan), ("cpu_seconds", 0, np.nan), ("finished", 2, np.nan), ("error", 1, ""),
    ("ideal_error", 0, "")])
def test_a_garbled_record_is_named_by_readers_and_rewritten_as_unknown(clean, copy, spec, inproc, name,
                                                                         index, fill):
    """A done item's time or error text that no longer decodes: open_dataset raises the
    project's CorruptStoreError naming it (not zstd's RuntimeError); the resume rewrites it as
    the fill value (NaN: the time is lost; a done item's error text is empty), keeps the
    samples, says so, and everything else is the clean store's bit for bit."""
    _chunk(copy, name, index).write_bytes(b"zzzz")
    with pytest.raises(CorruptStoreError, match=f"'{name}' cannot be read at .* {index} .*--resume"):
        open_dataset(copy)[name].load()
    report = generate(spec, copy, resume=True, scheduler=inproc)
    assert (report.computed, report.repaired) == (0, 0)
    assert report.cleared == ((name, 1),) and f"{name} of 1 " in report.summary()
    assert_same_store(clean, copy)
    stored = open_dataset(copy)[name].values
    reference = np.asarray(zarr.open_group(str(clean), mode="r")[name][...])
    others = np.arange(len(stored)) != index
    if name in PROVENANCE:
        assert np.isnan(stored[index]) and np.array_equal(stored[others], reference[others])
    else:
        assert stored[index] == fill and np.array_equal(stored, reference)
    assert generate(spec, copy, resume=True, scheduler=inproc).cleared == ()


# --- C: readers verify every sample -------------------------------------------------------------------
def _overwrite_deformation(path: Path) -> int:
    """Sample 1's deformation chunk replaced by sample 0's: it decodes, to other values."""
    group = zarr.open_group(str(path), mode="r+")
    group["deformation"][1] = group["deformation"][0]
    return 1


def _delete_intensity(path: Path) -> int:
    """Sample 2's intensity chunk removed: it reads as the fill value, NaN."""
    (path / "intensity" / "c" / "2" / "0" / "0").unlink()
    return 2


@pytest.mark.parametrize("damage", [_overwrite_deformation, _delete_intensity])
def test_readers_refuse_a_sample_that_fails_its_checksum_and_a_resume_recomputes_it(
        clean, copy, spec, inproc, damage):
    bad = damage(copy)
    reference = zarr.open_group(str(clean), mode="r")
    for representation in ("intensity", "fa_sphere"):
        loader = Loader(str(copy), representation=representation, split="all", normalise=False)
        with pytest.raises(CorruptSampleError, match=f"sample {bad}'s stored data") as info:
            list(loader)
        assert str(copy) in str(info.value) and "--resume" in str(info.value)
    ds = open_dataset(copy)
    with pytest.raises(CorruptSampleError, match=f"sample {bad}'s"):
        sample_fieldmap(ds, bad)
    good = 3
    assert np.array_equal(sample_fieldmap(ds, good)["intensity"].values, reference["intensity"][good])
    _, y = Loader(str(copy), split="all", normalise=False).raw([good])
    assert np.array_equal(y[0], reference["deformation"][good], equal_nan=True)
    report = generate(spec, copy, resume=True, scheduler=inproc)
    assert (report.repaired, report.computed) == (1, 1)
    assert_same_store(clean, copy)
    assert len(list(Loader(str(copy), split="all", batch_size=4))) == 1


def _swap_samples(path: Path, a: int, b: int) -> None:
    """Every per-sample chunk (data, checksum, status) of samples ``a`` and ``b`` exchanged, as
    a bad merge or copy of stores would leave them."""
    group = zarr.open_group(str(path), mode="r")
    for name, arr in group.arrays():
        if tuple(arr.metadata.dimension_names or ())[:1] != ("sample",) or arr.chunks[0] != 1:
            continue
        folder = path / name / "c"  # a chunk that holds the fill value is not written at all
        first, second, aside = folder / str(a), folder / str(b), folder / "swap"
        if first.exists():
            first.rename(aside)
        if second.exists():
            second.rename(first)
        if aside.exists():
            aside.rename(second)


def test_a_sample_moved_to_another_sample_s_place_fails_its_checksum(clean, copy, spec, inproc):
    """A validation sample's chunks swapped with a training sample's: each chunk is intact and
    matches the checksum it moved with, but not the sample it now stands for, so the training
    split never serves the validation sample, and a resume recomputes both."""
    split = np.asarray(zarr.open_group(str(clean), mode="r")["split"][...])
    validation, train = int(np.flatnonzero(split == 1)[0]), int(np.flatnonzero(split == 0)[0])
    _swap_samples(copy, validation, train)
    with pytest.raises(CorruptSampleError, match=f"sample {train}'s stored data"):
        list(Loader(str(copy), split="train", normalise=False))
    with pytest.raises(CorruptSampleError, match=f"sample {validation}'s stored data"):
        sample_fieldmap(open_dataset(copy), validation)
    report = generate(spec, copy, resume=True, scheduler=inproc)
    assert (report.repaired, report.computed) == (2, 2)
    assert_same_store(clean, copy)


def test_a_sample_copied_from_a_store_of_another_spec_fails_its_checksum(clean, copy, spec, inproc,
                                                                        tmp_path):
    """QA: a sibling store made from another spec with the same seed (another mesh
    resolution) has the same samples' seeds and indices; sample 2's chunks (data, checksum,
    status) copied from it into this store passed the resume (exit 0) and the readers. Since
    format 3 the checksums hash the spec's fingerprint: refused, then recomputed."""
    text = small_demo_text(samples=4, measurement=False).replace("resolution_m = 1.0", "resolution_m = 1.2")
    other_spec = parse_spec(text, source="other.toml", base=ROOT / "scenes")
    assert other_spec.fingerprint != spec.fingerprint
    other = tmp_path / "other.zarr"
    generate(other_spec, other, scheduler=inproc)
    group = zarr.open_group(str(other), mode="r")
    for name, arr in group.arrays():
        if tuple(arr.metadata.dimension_names or ())[:1] != ("sample",) or arr.chunks[0] != 1:
            continue
        source, target = other / name / "c" / "2", copy / name / "c" / "2"
        if target.is_dir():
            shutil.rmtree(target)
        elif target.exists():
            target.unlink()
        if source.is_dir():
            shutil.copytree(source, target)
        elif source.exists():
            shutil.copyfile(source, target)
    assert not np.array_equal(zarr.open_group(str(copy), mode="r")["intensity"][2],
                              zarr.open_group(str(clean), mode="r")["intensity"][2])
    with pytest.raises(CorruptSampleError, match="sample 2's stored data"):
        sample_fieldmap(open_dataset(copy), 2)
    report = generate(spec, copy, resume=True, scheduler=inproc)
    assert (report.repaired, report.computed) == (1, 1)
    assert_same_store(clean, copy)


def test_a_format_2_store_is_still_read_and_resumed(clean, copy, spec, inproc):
    """Stores made before the fingerprint joined the checksums (format 2) keep their weaker
    checksums and stay readable and resumable: rewritten here as format 2 wrote them."""
    from raysim.dataset import integrity

    group = zarr.open_group(str(copy), mode="r+")
    names = zstore.data_names(group)
    for i in range(group["status"].shape[0]):
        values = {name: np.asarray(group[name][i]) for name in names}
        group["checksum"][i] = integrity.sample_checksum(values, i, int(group["seed"][i]))
    for f in range(group["ideal_status"].shape[0]):
        group["ideal_checksum"][f] = integrity.ideal_checksum(np.asarray(group["intensity_ideal"][f]), f)
    group.attrs["raysim_dataset_format"] = 2
    integrity.record_static(group, spec)  # what format-2 creation recorded with its format
    assert len(list(Loader(str(copy), split="all", batch_size=4))) == 1
    assert sample_fieldmap(open_dataset(copy), 1)["intensity"].shape == (20, 72)
    report = generate(spec, copy, resume=True, scheduler=inproc)
    assert report.repaired == 0 and report.computed == 0


def test_a_store_of_the_previous_format_is_refused_in_one_line(copy, spec, inproc):
    """A store of format 1 (its checksums do not record which sample they are): readers and a
    resume refuse it in one line saying it comes from an older raysim, and touch nothing."""
    group = zarr.open_group(str(copy), mode="r+")
    group.attrs["raysim_dataset_format"] = 1
    before = _files(copy)
    for read in (lambda: Loader(str(copy), split="all"), lambda: open_dataset(copy),
                 lambda: generate(spec, copy, resume=True, scheduler=inproc)):
        with pytest.raises(DatasetError, match="made by an older raysim .dataset store format 1") as info:
            read()
        assert str(copy) in str(info.value) and "\n" not in str(info.value)
    assert _files(copy) == before


@pytest.mark.parametrize("array", ["intensity", "deformation", "checksum"])
def test_readers_refuse_a_garbled_array_metadata_in_one_line_naming_it(copy, array):
    """Not a raw json.JSONDecodeError: the project's CorruptStoreError, naming the array."""
    (copy / array / "zarr.json").write_text('{"zarr_format": 3, "node_ty')
    for read in (lambda: Loader(str(copy), split="all"), lambda: open_dataset(copy)):
        with pytest.raises(CorruptStoreError) as info:
            read()
        message = str(info.value)
        assert str(copy) in message and f"'{array}'" in message and "\n" not in message


def test_a_failed_ideal_and_a_lost_frequency_are_one_line_errors(copy):
    (copy / "intensity_ideal" / "c" / "0" / "0" / "0").unlink()
    with pytest.raises(CorruptSampleError, match="ideal intensity of 3e\\+08 Hz"):
        Loader(str(copy), representation="fa_sphere", split="all").raw([0])
    # a store that lost its frequencies: refused when opened, naming the array
    (copy / "frequency" / "c" / "0").unlink()
    with pytest.raises(CorruptStoreError, match="'frequency'"):
        sample_fieldmap(open_dataset(copy), 0)


def _cf_offset(path: Path) -> None:
    """``add_offset`` added to ``split`` and ``sample``: the stored values are unchanged, but
    xarray would return split + 1 and samples 1..n."""
    for name in ("split", "sample"):
        meta = path / name / "zarr.json"
        data = json.loads(meta.read_text())
        data["attributes"]["add_offset"] = 1
        meta.write_text(json.dumps(data))


def _no_static_checksums(path: Path) -> None:
    """``static_checksums`` removed and ``diameter`` edited: without the first, nothing would
    catch the second."""
    group = zarr.open_group(str(path), mode="r+")
    del group.attrs[STATIC_ATTR]
    group.attrs["diameter"] = 10.0


@pytest.mark.parametrize(("damage", "named", "rewritten"), [
    (_cf_offset, "its array 'sample'", ("sample attributes", "split attributes")),
    (_no_static_checksums, f"its attribute '{STATIC_ATTR}'", ("attribute diameter",))])
def test_readers_refuse_edited_metadata_and_a_resume_rewrites_it(clean, copy, spec, inproc, damage, named,
                                                                  rewritten):
    damage(copy)
    for read in (lambda: Loader(str(copy), split="all"), lambda: open_dataset(copy)):
        with pytest.raises(CorruptStoreError, match="--resume") as info:
            read()
        assert named in str(info.value) and "\n" not in str(info.value)
    report = generate(spec, copy, resume=True, scheduler=inproc)
    assert report.rewritten == rewritten and report.computed == 0
    assert_same_store(clean, copy)
    ds = open_dataset(copy)
    reference = zarr.open_group(str(clean), mode="r")
    assert np.array_equal(ds["split"].values, reference["split"][...])
    assert np.array_equal(ds["sample"].values, np.arange(spec.samples))


# --- D: what a run killed while creating its store left -----------------------------------------------
_KILLED_WHILE_CREATING = """
import os, signal, sys
from pathlib import Path
from raysim.dataset import parse_spec
from raysim.dataset import store
spec = parse_spec(sys.stdin.read(), source="small4.toml", base=Path(sys.argv[2]))
fill = store._fill
def fill_and_die(group, spec):
    fill(group, spec)
    os.kill(os.getpid(), signal.SIGKILL)
store._fill = fill_and_die
store.create(sys.argv[1], spec)
"""


def test_a_run_killed_while_creating_leaves_what_the_next_run_removes(spec, tmp_path):
    target = tmp_path / "new.zarr"
    result = subprocess.run([sys.executable, "-c", textwrap.dedent(_KILLED_WHILE_CREATING), str(target),
                             str(ROOT / "scenes")], input=spec.text, capture_output=True, text=True,
                            timeout=120, cwd=ROOT)
    assert result.returncode == -9, result.stderr
    (dead,) = [p for p in tmp_path.iterdir() if p.name != "new.zarr"]
    assert not target.exists() and (dead / "zarr.json").is_file()  # a whole scratch store, left
    live = tmp_path / f"{writer_prefix(target)}0123abcd.tmp"  # a run still creating it: this one
    live.mkdir()
    legacy_old, legacy_new = tmp_path / ".new.zarr.00aa11bb.creating", tmp_path / ".new.zarr.22cc33dd.creating"
    for folder in (legacy_old, legacy_new):
        folder.mkdir()
    two_days_ago = time.time() - 2 * 86400
    os.utime(legacy_old, (two_days_ago, two_days_ago))
    group = zstore.create(str(target), spec)
    assert (zstore.status(group) == zstore.PENDING).all()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["new.zarr", live.name, legacy_new.name])
