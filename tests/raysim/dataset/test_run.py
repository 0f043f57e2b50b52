"""Dataset runs on Dask: physical samples in the store, identical reruns, a killed client
resumed, failures recorded, and a real distributed run (scheduler and worker processes)."""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import zarr

from raysim.dataset import (
    DatasetError,
    generate,
    load_spec,
    open_dataset,
    sample_fieldmap,
    sample_intensity,
)
from raysim.dataset import store as zstore
from raysim.dataset import worker as dataset_worker
from raysim.dataset.models import RimAstigmatism
from raysim.maps.fieldmap import validate
from raysim.maps.sphere import ideal_go_cell_mean
from raysim.surface.deformation import GaussianBumps, PanelRigid
from tests.cli import popen_cli, run_cli
from tests.processes import dask_processes, kill_group, wait_until, worker_processes
from tests.reference_zernike import zernike_sum

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[3]
DEMO = ROOT / "scenes" / "dataset_demo.toml"
RUN_TIMEOUT = 240  # s, for any command below
PROVENANCE = {"seconds", "cpu_seconds", "finished"}  # per-run bookkeeping: when and how long, not data


@pytest.fixture(scope="module")
def spec():
    return load_spec(DEMO)


@pytest.fixture(scope="module")
def reference(tmp_path_factory, spec, inproc):
    """The demo dataset made once, uninterrupted, by one worker."""
    path = tmp_path_factory.mktemp("reference") / "demo.zarr"
    report = generate(spec, path, scheduler=inproc)
    assert report.done == spec.samples and report.failed == 0 and report.workers == 1
    return path


def _arrays(path: Path) -> dict[str, np.ndarray]:
    group = zarr.open_group(str(path), mode="r")
    return {name: np.asarray(arr[...]) for name, arr in group.arrays() if name not in PROVENANCE}


def assert_same_store(a: Path, b: Path) -> None:
    """Every data array bit-identical (NaN where NaN), the same attributes but the date."""
    left, right = _arrays(a), _arrays(b)
    assert sorted(left) == sorted(right)
    for name in left:
        x, y = left[name], right[name]
        same = np.array_equal(x, y, equal_nan=True) if x.dtype.kind == "f" else np.array_equal(x, y)
        assert same, f"array {name!r} differs"
    attrs = [dict(zarr.open_group(str(p), mode="r").attrs) for p in (a, b)]
    for d in attrs:
        d.pop("created")
    assert attrs[0] == attrs[1]


def _markers(path: Path) -> set[int]:
    """Samples whose completion marker exists (one chunk file per sample; zarr writes each
    under a temporary ``N.<hex>.partial`` name first, which a listing may catch)."""
    folder = path / "status" / "c"
    return {int(p.name) for p in folder.iterdir() if p.name.isdigit()} if folder.is_dir() else set()


class _ZernikeReference:
    """Zernike sum from the tests' Jacobi-polynomial reference (tests/reference_zernike.py)."""

    def __init__(self, terms, a):
        self.terms, self.a = terms, a

    def __call__(self, x, y):
        return zernike_sum(self.terms, self.a, x, y)


def _rebuild(ds, i: int, spec) -> dict[str, object]:
    """Each error of sample i rebuilt from the stored parameters with the plain classes."""
    s = ds.isel(sample=i)
    a = 0.5 * spec.scene.D
    terms = tuple((int(n), int(m), float(c)) for n, m, c in zip(
        ds["zernike_term_n"].values, ds["zernike_term_m"].values, s["zernike_coefficient"].values,
        strict=True))
    parts: dict[str, object] = {"zernike": _ZernikeReference(terms, a)}
    if int(s["bumps_present"]):
        rows = np.column_stack([s[f"bumps_{k}"].values for k in ("x", "y", "amplitude", "sigma")])
        parts["bumps"] = GaussianBumps(tuple(map(tuple, rows[np.isfinite(rows).all(axis=1)])))
    parts["panel_rigid"] = PanelRigid(spec.scene.panels, s["panel_rigid_piston"].values,
                                      s["panel_rigid_tilt_x"].values, s["panel_rigid_tilt_y"].values)
    parts["gravity"] = RimAstigmatism(float(s["gravity_amplitude"]), float(s["gravity_exponent"]),
                                      float(s["gravity_angle"]), a)
    return parts


def test_store_holds_distinct_physical_samples(reference, spec, monkeypatch):
    ds = open_dataset(reference).load()
    n = spec.samples
    assert (ds["status"].values == 1).all() and (ds["error"].values == "").all()
    assert int(ds["split"].sum()) == 2
    sphere = spec.scene.sphere
    area = sphere.cell_area()  # sr per cell on the unit sphere scaled by R^2 (m^2)
    ideal = ds["intensity_ideal"].values[0]
    # power through the sphere = the lit aperture: pi a^2 less the panel gaps (faceted rim)
    lit = np.pi * (spec.scene.D / 2) ** 2 - spec.scene.panels.gap_area()
    assert np.sum(ideal * area) == pytest.approx(lit, rel=3e-3)
    # the ideal ring means follow the closed-form GO cell means (2F / (1 + cos))^2 / R^2
    edges = sphere.theta_edges
    expected = ideal_go_cell_mean(edges[:-1], edges[1:], spec.scene.F, sphere.radius, spec.scene.D)
    inner = sphere.theta < np.radians(70.0)
    ratio = ideal.mean(axis=1)[inner] / expected[inner]
    assert np.median(np.abs(ratio - 1.0)) < 5e-3
    intensity = ds["intensity"].values
    for i in range(n):
        # the deformation moves power about but the sphere still receives all of it
        assert np.sum(intensity[i] * area) == pytest.approx(np.sum(ideal * area), rel=2e-3)
        both = (ideal > 1.0) & (intensity[i] > 1.0)
        fa = ideal[both] / intensity[i][both] - 1.0
        assert 1e-4 < np.median(np.abs(fa)) < 0.2  # a real but perturbative signal
        for j in range(i):
            assert np.max(np.abs(intensity[i] - intensity[j])) > 1e-3
    # the stored maps are the sum of the stored errors; each error has its drawn RMS
    x, y = np.meshgrid(ds["x"].values, ds["y"].values)
    inside = np.hypot(x, y) < spec.scene.D / 2
    for i in range(n):
        parts = _rebuild(ds, i, spec)
        total = np.zeros(inside.sum())
        for name, part in parts.items():
            values = part(x[inside], y[inside])
            total += values
            assert np.sqrt(np.mean(values**2)) == pytest.approx(float(ds[f"{name}_rms"][i]), rel=1e-6)
        stored = ds["deformation"].values[i]
        assert np.isnan(stored[~inside]).all()
        assert np.allclose(stored[inside], total, rtol=1e-9, atol=1e-15)
        assert float(ds["rms"][i]) == pytest.approx(np.sqrt(np.mean(total**2)), rel=1e-9)
    # a sample read back as a FieldMap passes the FieldMap contract
    fieldmap = validate(sample_fieldmap(ds, 3))
    assert np.array_equal(fieldmap["intensity"].values, intensity[3])
    assert np.array_equal(fieldmap["intensity_ideal"].values, ideal)
    assert fieldmap.attrs["diameter"] == spec.scene.D and fieldmap.attrs["sample"] == 3
    # any sample regenerates alone, bit for bit (one thread per launch, as in the workers)
    monkeypatch.setenv("RAYSIM_THREADS", "1")
    for i in (0, n - 1):
        deformation, values = sample_intensity(spec, i)
        assert np.array_equal(values, intensity[i])
        assert np.array_equal(deformation, ds["deformation"].values[i], equal_nan=True)


def test_killed_client_resumes_to_the_same_store(reference, spec, tmp_path, inproc):
    """Two local worker processes (the CLI's default cluster), the client and then its
    workers killed with SIGKILL after the first sample, then resumed by another cluster: the
    same arrays as the reference made by one worker, and the samples done before the kill
    untouched."""
    # a sample takes a fraction of a second: where the kill lands a second late (this process
    # waiting for a core on a busy machine), the workers have finished all 8 and there is
    # nothing to resume (seen once in a CI run); such a lost race is run again, on a new store
    for attempt in range(3):
        store = tmp_path / f"killed{attempt}.zarr"
        done = _killed_after_the_first_sample(store)
        if 0 < len(done) < spec.samples:
            break
    assert 0 < len(done) < spec.samples, f"three runs finished every sample before the kill: {done}"
    group = zarr.open_group(str(store), mode="r")
    finished = np.asarray(group["finished"][...])
    report = generate(spec, store, resume=True, scheduler=inproc)
    assert (report.done, report.skipped, report.computed) == (spec.samples, len(done),
                                                              spec.samples - len(done))
    assert not report.nothing_to_resume and "--resume" not in report.summary()
    assert_same_store(reference, store)
    after = np.asarray(zarr.open_group(str(store), mode="r")["finished"][...])
    kept = sorted(done)
    assert np.array_equal(after[kept], finished[kept])  # done samples were not redone


def _killed_after_the_first_sample(store: Path) -> set[int]:
    """``raysim dataset`` of the demo on two local workers into ``store``, the client and its
    workers killed with SIGKILL as soon as the first sample's marker is there (or the run has
    ended); the samples done."""
    proc = popen_cli("dataset", str(DEMO), "-o", str(store), "--workers", "2", stdout=subprocess.DEVNULL,
                     stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + RUN_TIMEOUT
        while not _markers(store) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        proc.send_signal(signal.SIGKILL)  # the client; its local workers lose their scheduler
        # and are killed at once too: left to notice, they finished the samples they held
        # (all 8 of them on a busy machine), and the kill must leave some undone
        with contextlib.suppress(ProcessLookupError):  # a run that ended has no group left
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        kill_group(proc)
    return _markers(store)


def test_a_resume_with_no_store_says_it_made_a_new_one(reference, spec, tmp_path, inproc):
    """QA: --resume with no store there (a mistyped path) started a new store without a word,
    where simulate says so and scan refuses; the store is the uninterrupted one."""
    store = tmp_path / "typo.zarr"
    report = generate(spec, store, resume=True, scheduler=inproc)
    assert report.nothing_to_resume and report.computed == spec.samples
    assert f"--resume: no store was at {store} to complete, so a new one was made" in report.summary()
    assert_same_store(reference, store)


def test_a_store_of_another_spec_is_refused(reference, spec, tmp_path):
    other = tmp_path / "other.toml"
    other.write_text(DEMO.read_text().replace("seed = 20240917", "seed = 1"))
    before = _arrays(reference)
    result = run_cli("dataset", str(other), "-o", str(reference), "--resume", timeout=RUN_TIMEOUT)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr and "different spec" in lines[0]
    with pytest.raises(DatasetError, match="already exists; add --resume"):
        generate(spec, reference)
    after = _arrays(reference)
    assert all(np.array_equal(before[k], after[k], equal_nan=before[k].dtype.kind == "f") for k in before)


def test_failed_samples_are_recorded_and_the_others_go_on(reference, spec, tmp_path, monkeypatch, inproc):
    real = dataset_worker.draw_sample

    def flaky(spec_, index, seed=None):
        if index in (2, 5):
            raise RuntimeError(f"injected failure of sample {index}")
        return real(spec_, index, seed)

    store = tmp_path / "flaky.zarr"
    monkeypatch.setattr(dataset_worker, "draw_sample", flaky)
    report = generate(spec, store, scheduler=inproc)
    assert (report.done, report.failed) == (spec.samples - 2, 2)
    assert sorted(i for i, _ in report.failures) == [2, 5]
    ds = open_dataset(store)
    assert ds["status"].values.tolist() == [1, 1, 2, 1, 1, 2, 1, 1]
    assert ds["error"].values[5] == "RuntimeError: injected failure of sample 5"
    monkeypatch.setattr(dataset_worker, "draw_sample", real)
    again = generate(spec, store, scheduler=inproc, resume=True)
    assert (again.done, again.failed, again.computed) == (spec.samples, 0, 2)
    assert_same_store(reference, store)


def test_a_full_disk_names_the_store_and_a_resume_completes_it(reference, spec, tmp_path, monkeypatch,
                                                               inproc):
    """QA: a disk that filled while a dataset was written ended in "No space left on device"
    alone: not which store, nor that --resume completes it. The disk fills at sample 3 (its
    write and its failure marker both fail, as they would); the run stops with one line naming
    the store and --resume, the samples finished before are kept, and the resume on a freed
    disk gives the uninterrupted store."""
    real_draw, real_failed = dataset_worker.draw_sample, zstore.Writer.failed

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    def draw(spec_, index, seed=None):
        if index >= 3:
            full()
        return real_draw(spec_, index, seed)

    store = tmp_path / "full.zarr"
    monkeypatch.setattr(dataset_worker, "draw_sample", draw)
    monkeypatch.setattr(zstore.Writer, "failed", full)
    with pytest.raises(DatasetError, match=r"full\.zarr: no space left on the device; .*--resume"):
        generate(spec, store, scheduler=inproc)
    assert 0 < int(np.sum(open_dataset(store)["status"].values == zstore.DONE)) < spec.samples
    monkeypatch.setattr(dataset_worker, "draw_sample", real_draw)
    monkeypatch.setattr(zstore.Writer, "failed", real_failed)
    generate(spec, store, scheduler=inproc, resume=True)
    assert_same_store(reference, store)


def test_the_store_size_estimate_bounds_the_store_written(reference, spec):
    """The estimate that refuses a store too large for its disk is an upper bound of what a
    store takes (blocks on disk, as `du` counts them), and not far above it."""
    from raysim.dataset.store_layout import store_bytes

    on_disk = sum(p.stat().st_blocks * 512 for p in reference.rglob("*") if p.is_file())
    assert on_disk <= store_bytes(spec) <= 2 * on_disk, (on_disk, store_bytes(spec))


def test_a_store_too_large_for_its_disk_is_refused_before_any_work(spec, tmp_path, monkeypatch):
    """QA: a 10-million-sample spec was accepted on a disk with 78 GB free for about 200 GB of
    store, and started computing."""
    from raysim.dataset import run as dataset_run
    from raysim.dataset.run import check_run_options
    from raysim.dataset.store_layout import store_bytes

    real = shutil.disk_usage
    need = store_bytes(spec)
    store = tmp_path / "big.zarr"
    monkeypatch.setattr(dataset_run.shutil, "disk_usage",
                        lambda where: real(where)._replace(free=need - 1))
    with pytest.raises(DatasetError, match=r"big\.zarr: the store would take up to .* GB free"):
        check_run_options(spec, store)
    assert not store.exists()
    monkeypatch.setattr(dataset_run.shutil, "disk_usage",
                        lambda where: real(where)._replace(free=need))
    check_run_options(spec, store)


def test_separate_scheduler_and_worker_with_a_worker_killed(reference, spec, tmp_path):
    """A `dask scheduler` and a `dask worker` process on loopback, the CLI as client; the
    worker process is killed after the first sample and its nanny restarts it: the store
    completes, identical to the reference."""
    with dask_processes(1) as (address, nanny_pid):
        store = tmp_path / "distributed.zarr"
        run = popen_cli("dataset", str(DEMO), "-o", str(store), "--scheduler", address, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
        try:
            wait_until(lambda: bool(_markers(store)) or run.poll() is not None, RUN_TIMEOUT,
                        "a first sample")
            workers = worker_processes(nanny_pid)
            killed = bool(workers) and run.poll() is None and len(_markers(store)) < spec.samples
            for pid in workers:  # the worker process under the nanny: the nanny restarts it
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)
            out, err = run.communicate(timeout=RUN_TIMEOUT)
        finally:
            if run.poll() is None:
                run.kill()
                run.wait(timeout=15)
        assert killed, "the run ended before a worker could be killed"
        assert run.returncode == 0, err
        assert f"{spec.samples}/{spec.samples} samples done" in out and "on 1 worker in" in out
        assert_same_store(reference, store)


def _sample_chunks(path: Path, name: str, index: int) -> list[Path]:
    first = path / name / "c" / str(index)
    return [first] if first.is_file() else sorted(f for f in first.rglob("*") if f.is_file())


def test_a_resume_recomputes_samples_whose_chunks_were_removed_or_truncated(reference, spec, tmp_path,
                                                                            inproc):
    """Kill-and-corrupt: a copy of the reference with samples 4.. pending (as a kill leaves
    them), sample 0's deformation chunk removed, sample 1's intensity chunk truncated to 10
    bytes, sample 2's checksum and the first frequency's ideal intensity removed; the resume finds the four,
    computes them again with the pending ones, and the store is the uninterrupted one bit for bit."""
    store = tmp_path / "corrupt.zarr"
    shutil.copytree(reference, store)
    group = zarr.open_group(str(store), mode="r+")
    names = zstore.data_names(zarr.open_group(str(reference), mode="r"))
    # as a kill leaves them: no marker, and nothing the task writes (a checksum with no marker
    # is a finished sample whose marker was lost, which a resume counts as repaired)
    zstore.reset(group, range(4, spec.samples), [], names)
    (removed,) = _sample_chunks(store, "deformation", 0)
    removed.unlink()
    (truncated,) = _sample_chunks(store, "intensity", 1)
    truncated.write_bytes(truncated.read_bytes()[:10])
    _sample_chunks(store, "checksum", 2)[0].unlink()
    _sample_chunks(store, "intensity_ideal", 0)[0].unlink()
    assert zstore.verify(zarr.open_group(str(store), mode="r+"), str(store), names) == ([0, 1, 2], [0])
    report = generate(spec, store, resume=True, scheduler=inproc)
    assert (report.repaired, report.skipped, report.computed) == (4, 1, spec.samples - 1)
    assert "4 done items failed verification and were recomputed" in report.summary()
    assert_same_store(reference, store)


def test_a_store_whose_checksums_were_removed_is_recomputed(reference, spec, tmp_path, inproc):
    """A store of this format always had its ``checksum`` array (an older raysim's is refused by
    its format): removed, it is made again from the layout, no sample can be verified, and all
    are computed again, to the uninterrupted store."""
    store = tmp_path / "old.zarr"
    shutil.copytree(reference, store)
    shutil.rmtree(store / "checksum")
    report = generate(spec, store, resume=True, scheduler=inproc)
    assert report.repaired == report.computed == spec.samples and "checksum metadata" in report.rewritten
    assert_same_store(reference, store)


def test_a_killed_and_corrupted_store_resumes_to_the_uninterrupted_one(reference, spec, tmp_path, inproc):
    """SIGKILL to the whole run (client and workers) after two samples, then one done sample's
    deformation chunk removed and another's intensity chunk truncated: the resume finds both,
    computes them again, and the store is the uninterrupted one bit for bit."""
    store = tmp_path / "killed.zarr"
    proc = popen_cli("dataset", str(DEMO), "-o", str(store), "--workers", "1", stdout=subprocess.DEVNULL,
                     stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        wait_until(lambda: proc.poll() is not None or len(_markers(store)) >= 2, RUN_TIMEOUT,
                   "two samples")
        assert proc.poll() is None, "the run ended before it could be killed"
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        kill_group(proc)
    status = np.asarray(zarr.open_group(str(store), mode="r")["status"][...])
    first, second = np.flatnonzero(status == 1)[:2]
    (removed,) = _sample_chunks(store, "deformation", int(first))
    removed.unlink()
    (truncated,) = _sample_chunks(store, "intensity", int(second))
    truncated.write_bytes(truncated.read_bytes()[:10])
    report = generate(spec, store, resume=True, scheduler=inproc)
    assert report.repaired == 2 and report.done == spec.samples
    assert_same_store(reference, store)


@pytest.mark.parametrize(("garbled", "message"), [("zarr.json", "not a Zarr store")])
def test_a_store_whose_metadata_cannot_be_read_is_refused_in_one_line(reference, spec, tmp_path, inproc,
                                                                      garbled, message):
    store = tmp_path / "garbled.zarr"
    shutil.copytree(reference, store)
    (store / garbled).write_text("{not json")
    with pytest.raises(DatasetError, match=message) as info:
        generate(spec, store, resume=True, scheduler=inproc)
    assert str(store) in str(info.value) and "\n" not in str(info.value)
    assert (store / garbled).read_text() == "{not json"  # left as it was, for the user to decide


def test_a_resume_that_only_repairs_an_ideal_intensity_says_so(reference, spec, tmp_path, inproc):
    """Every sample done, one frequency's ideal intensity chunk lost: the resume recomputed it
    and printed "nothing left to compute" (found by damaging stores between runs)."""
    store = tmp_path / "ideal.zarr"
    shutil.copytree(reference, store)
    _sample_chunks(store, "intensity_ideal", 0)[0].unlink()
    report = generate(spec, store, resume=True, scheduler=inproc)
    assert (report.repaired, report.computed) == (1, 0)
    line = report.summary()
    assert "nothing left to compute" not in line
    assert "1 done item failed verification and was recomputed" in line
    assert_same_store(reference, store)


def test_a_store_made_with_other_versions_is_neither_resumed_nor_written_by_a_worker(reference, spec,
                                                                                     tmp_path, monkeypatch):
    """The store records the versions its samples depend on; a resume under another numpy (or
    a Dask worker elsewhere with another Warp) added samples that differ from the others in
    their last bits, exit 0. Both are refused, naming what changed; the store is untouched."""
    store = tmp_path / "copy.zarr"
    shutil.copytree(reference, store)
    before = _arrays(store)
    real = zstore.versions()
    for key, name in (("version_numpy", "numpy"), ("version_warp", "warp")):
        monkeypatch.setattr(zstore, "versions", lambda key=key: {**real, key: "0.0.1"})
        recorded = real[key]
        with pytest.raises(DatasetError, match=f"other versions .*\\({name} {recorded} -> 0.0.1\\)"):
            generate(spec, store, resume=True, workers=1)
        dataset_worker.context.cache_clear()
        with pytest.raises(DatasetError, match=f"{name} {recorded} -> 0.0.1"):
            dataset_worker.context(str(store), spec.fingerprint)
    monkeypatch.setattr(zstore, "versions", lambda: {**real, "version_dask": "0.0.1"})  # no value depends on it
    dataset_worker.context.cache_clear()
    assert dataset_worker.context(str(store), spec.fingerprint).spec.fingerprint == spec.fingerprint
    dataset_worker.context.cache_clear()
    after = _arrays(store)
    assert all(np.array_equal(before[k], after[k], equal_nan=before[k].dtype.kind == "f") for k in before)
