"""Wave-optics FieldMaps in blocks of sphere points on Dask (a cluster in this process): the
single-process FieldMap bit for bit whatever the split, resumable, and one-line refusals."""

from __future__ import annotations

import itertools
import json
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from raysim.distributed import ClusterError, connect, scheduler_address
from raysim.distributed import blocks as dblocks
from raysim.distributed.blocks import block_bounds, run_blocks
from raysim.distributed.partial import PartialStore, partial_path
from raysim.distributed.simulate import scene_job
from raysim.distributed.simulate import simulate as simulate_blocks
from raysim.maps.fieldmap import load
from raysim.optics.illumination import Illumination
from raysim.optics.sources import Sources
from raysim.scene.scene import parse_scene
from raysim.simulate import Options, simulate
from raysim.surface.mesh import reflectors_for
from tests.raysim.distributed.conftest import SMALL, assert_same_fieldmap

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def scene():
    return parse_scene(SMALL)


@pytest.fixture(scope="module")
def single(scene):
    """The single-process FieldMaps: po, and po+ptd with the complex fields saved."""
    return {"po": simulate(scene, "po"), "po+ptd": simulate(scene, "po+ptd", save_field=True)}


def test_each_point_sums_the_same_elements_whatever_the_split(scene):
    """Sources radiated onto uneven blocks (starts at multiples of 4) give the sums of the whole
    grid bit for bit, and the elements kept after the first pass are the ones streamed."""
    _, deformed = reflectors_for(scene)
    wave = Illumination.plane_wave(scene.source.frequency_hz, scene.source.direction, scene.source.e_hat)
    points = scene.sphere.points(deformed.F).reshape(-1, 3)
    whole = Sources(deformed, wave, 1.5, "rim", keep=False).radiate(points)
    kept = Sources(deformed, wave, 1.5, "rim", keep=True)
    cuts = [0, 4, 12, 100, 204, 320, len(points)]
    parts = [kept.radiate(points[lo:hi]) for lo, hi in itertools.pairwise(cuts)]
    assert kept._kept is not None  # the second and later blocks reuse the first pass's elements
    for kind in ("electric", "fringe"):
        joined = np.concatenate([p.sums[kind] for p in parts])
        assert np.array_equal(joined, whole.sums[kind]), kind
        assert np.abs(whole.sums[kind]).max() > 0
    assert sum(p.pairs for p in parts) == whole.pairs == kept.n_elements * len(points)


@pytest.mark.parametrize(("method", "block_size"), [("po", 40), ("po+ptd", 16), ("po+ptd", 100)])
def test_blocks_give_the_single_process_fieldmap(scene, single, inproc, tmp_path, method, block_size):
    out = tmp_path / "field.nc"
    seen = []
    ds = simulate_blocks(scene, out, method, scheduler=inproc, block_size=block_size,
                         save_field=method == "po+ptd", progress=lambda stage, f: seen.append((stage, f)))
    n_blocks = -(-scene.sphere.n_theta * scene.sphere.n_phi // block_size)
    assert_same_fieldmap(single[method], ds)
    assert_same_fieldmap(single[method], load(out))
    a = ds.attrs
    assert (a["blocks"], a["blocks_computed"], a["blocks_reused"], a["blocks_computed_twice"]) == \
        (n_blocks, n_blocks, 0, 0)
    assert a["block_element_sets"] == 1 and a["workers"] == 2
    assert seen[0] == (f"0 of {n_blocks} blocks", 0.0)
    assert seen[-1] == (f"{n_blocks} of {n_blocks} blocks", 1.0)
    assert not partial_path(out).exists()


def test_an_interrupted_run_resumes_without_computing_a_block_twice(scene, single, inproc, tmp_path):
    """Blocks 0, 3 and 5 computed by a first client that then stopped; the resumed run computes
    the rest only, and the FieldMap is the single-process one."""
    out = tmp_path / "field.nc"
    options = Options()
    job, description = scene_job(scene, "po", options, "cpu", 1, 40)
    path = partial_path(out)
    store = PartialStore.create(path, job.key, description, job.parts(), job.n_points, 40)
    bounds = block_bounds(job.n_points, 40)
    with connect(inproc) as cluster:
        run_blocks(cluster.client, job, [0, 3, 5], bounds, store)
    assert sorted(store.markers()) == [0, 3, 5]
    with pytest.raises(ClusterError, match="add --resume"):
        simulate_blocks(scene, out, "po", scheduler=inproc, block_size=40)
    with pytest.raises(ClusterError, match=r"differs in: frequency_hz"):
        simulate_blocks(scene.with_overrides(frequency_hz=1.1e9), out, "po", scheduler=inproc,
                        block_size=40, resume=True)
    ds = simulate_blocks(scene, out, "po", scheduler=inproc, block_size=40, resume=True)
    assert_same_fieldmap(single["po"], ds)
    a = ds.attrs
    assert (a["blocks_reused"], a["blocks_computed"], a["blocks_computed_twice"]) == (3, len(bounds) - 3, 0)


def test_a_block_already_marked_is_not_computed_again(scene, inproc, tmp_path):
    """A worker handed a block whose marker exists (Dask rerunning a task whose result died with
    its worker) skips it; the count of computations stays one."""
    job, description = scene_job(scene, "po", Options(), "cpu", 1, 64)
    store = PartialStore.create(tmp_path / "p.partial.zarr", job.key, description, job.parts(),
                                job.n_points, 64)
    bounds = block_bounds(job.n_points, 64)
    seen = []
    with connect(inproc) as cluster:
        run_blocks(cluster.client, job, [1], bounds, store, seen.append)
        run_blocks(cluster.client, job, [1, 2], bounds, store, seen.append)
    by_index = {(m["index"], m["skipped"]) for m in seen}
    assert by_index == {(1, False), (1, True), (2, False)}
    assert store.marker(1)["count"] == 1 and store.marker(2)["count"] == 1


def test_blocks_the_workers_cannot_store_are_written_by_the_client(scene, single, inproc, tmp_path,
                                                                   monkeypatch):
    """Workers without the output's file system return their blocks: same FieldMap."""
    monkeypatch.setattr(dblocks, "_reachable", lambda store, key: None)
    ds = simulate_blocks(scene, tmp_path / "f.nc", "po", scheduler=inproc, block_size=64)
    assert_same_fieldmap(single["po"], ds)
    assert ds.attrs["blocks_computed_twice"] == 0


def test_a_scene_changed_in_python_is_refused(scene, tmp_path, inproc):
    from dataclasses import replace

    changed = replace(scene, source=replace(scene.source, polarization=0.5))
    with pytest.raises(ClusterError, match="differs from its TOML text"):
        simulate_blocks(changed, tmp_path / "f.nc", "po", scheduler=inproc)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"method": "go", "workers": 2}, "apply to the wave methods"),
    ({"method": "po", "workers": 1, "block_size": 10}, "multiple of 4"),
    ({"method": "po", "scheduler": "nowhere"}, "not of the form tcp://HOST:PORT"),
    ({"method": "po", "workers": 0}, "workers must be >= 1"),
])
def test_bad_options_are_refused(scene, tmp_path, kwargs, message):
    with pytest.raises(ClusterError, match=message):
        simulate_blocks(scene, tmp_path / "f.nc", **kwargs)
    assert list(tmp_path.iterdir()) == []  # no output, no partial store left behind


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_an_unreachable_scheduler_is_one_line_naming_it(tmp_path):
    port = _closed_port()
    with pytest.raises(ClusterError, match=rf"tcp://127.0.0.1:{port}: connection refused"):
        with connect(f"tcp://127.0.0.1:{port}", timeout=5):
            pass
    scene_path = tmp_path / "small.toml"
    scene_path.write_text(SMALL)
    run = subprocess.run([sys.executable, "-m", "raysim.cli", "simulate", str(scene_path), "-o",
                          str(tmp_path / "f.nc"), "--scheduler", f"127.0.0.1:{port}"],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert run.returncode == 2, run.stderr
    assert len(run.stderr.strip().splitlines()) == 1 and f"tcp://127.0.0.1:{port}" in run.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["small.toml"]


def test_scheduler_addresses():
    assert scheduler_address("10.0.0.5:8786") == "tcp://10.0.0.5:8786"
    assert scheduler_address("tls://head.example.org:8786") == "tls://head.example.org:8786"
    assert scheduler_address("[::1]:8786") == "tcp://[::1]:8786"
    for bad in ("head", "tcp://head", "head:0", "head:70000", "http://head:80"):
        with pytest.raises(ClusterError):
            scheduler_address(bad)


def _chunk_files(store_path: Path, index: int) -> list[Path]:
    """The chunk files of block ``index`` in every part of a partial store."""
    out = []
    for part in sorted(p for p in store_path.iterdir() if (p / "zarr.json").is_file()):
        first = part / "c" / str(index)
        out += [first] if first.is_file() else sorted(f for f in first.rglob("*") if f.is_file())
    return out


def test_a_resume_recomputes_blocks_whose_chunks_were_removed_or_truncated(scene, single, inproc,
                                                                          tmp_path):
    """Kill-and-corrupt: blocks 0..4 done, then one block's chunks removed and another's
    truncated; the resume finds both by their checksums, computes them again and gives the
    single-process FieldMap bit for bit."""
    out = tmp_path / "field.nc"
    job, description = scene_job(scene, "po", Options(), "cpu", 1, 40)
    path = partial_path(out)
    store = PartialStore.create(path, job.key, description, job.parts(), job.n_points, 40)
    bounds = block_bounds(job.n_points, 40)
    with connect(inproc) as cluster:
        run_blocks(cluster.client, job, [0, 1, 2, 3, 4], bounds, store)
    assert store.verify() == []
    removed, truncated = _chunk_files(path, 1), _chunk_files(path, 3)
    assert removed and truncated
    for f in removed:
        f.unlink()
    for f in truncated:
        f.write_bytes(f.read_bytes()[:10])
    assert PartialStore.open(path).verify() == [1, 3]
    ds = simulate_blocks(scene, out, "po", scheduler=inproc, block_size=40, resume=True)
    assert_same_fieldmap(single["po"], ds)
    assert_same_fieldmap(single["po"], load(out))
    a = ds.attrs
    assert (a["blocks_repaired"], a["blocks_reused"], a["blocks_computed"]) == (2, 3, len(bounds) - 3)


def test_a_partial_store_with_unreadable_metadata_is_refused_in_one_line(scene, inproc, tmp_path):
    out = tmp_path / "field.nc"
    job, description = scene_job(scene, "po", Options(), "cpu", 1, 40)
    path = partial_path(out)
    PartialStore.create(path, job.key, description, job.parts(), job.n_points, 40)
    part = next(p for p in path.iterdir() if (p / "zarr.json").is_file())
    (part / "zarr.json").write_text("{garbled")
    with pytest.raises(ClusterError, match="delete it to start again") as info:
        simulate_blocks(scene, out, "po", scheduler=inproc, block_size=40, resume=True)
    assert str(path) in str(info.value) and "\n" not in str(info.value)
    assert path.exists()  # never destroyed: the user decides


def _every_block_done(scene, inproc, tmp_path: Path) -> tuple[Path, Path]:
    """(output, partial store) of the scene's PO run with every block of 40 points done."""
    out = tmp_path / "field.nc"
    job, description = scene_job(scene, "po", Options(), "cpu", 1, 40)
    path = partial_path(out)
    store = PartialStore.create(path, job.key, description, job.parts(), job.n_points, 40)
    bounds = block_bounds(job.n_points, 40)
    with connect(inproc) as cluster:
        run_blocks(cluster.client, job, list(range(len(bounds))), bounds, store)
    return out, path


def test_a_resume_brings_back_a_torn_context(scene, single, inproc, tmp_path):
    """Every block done and intact, but context.json torn: one block is computed again (it
    brings the context) and the FieldMap is the single-process one."""
    out, path = _every_block_done(scene, inproc, tmp_path)
    (path / "context.json").write_text('{"mesh": ')
    ds = simulate_blocks(scene, out, "po", scheduler=inproc, block_size=40, resume=True)
    assert_same_fieldmap(single["po"], ds)
    assert (ds.attrs["blocks_repaired"], ds.attrs["blocks_computed"]) == (1, 1)


def test_a_resume_rebuilds_an_edited_context_and_recomputes_swapped_blocks(scene, single, inproc,
                                                                           tmp_path):
    """Files that parse but lie: context.json with another diameter and focal length (the
    inversion reads them), and blocks 1 and 3 swapped, chunks and markers together (each
    marker's checksum matches the values beside it). Their checksums are bound to the run,
    the block and the part: all three are made again and the FieldMap is the single-process
    one (before: the edited dish's attributes and other points' intensities, exit 0)."""
    out, path = _every_block_done(scene, inproc, tmp_path)
    context = json.loads((path / "context.json").read_text())
    context["attrs"]["diameter"] += 1.0
    context["attrs"]["focal_length"] += 1.0
    (path / "context.json").write_text(json.dumps(context))
    one, three = _chunk_files(path, 1), _chunk_files(path, 3)
    for a, b in [*zip(one, three, strict=True),
                 (path / "blocks" / "000001.json", path / "blocks" / "000003.json")]:
        a_bytes = a.read_bytes()
        a.write_bytes(b.read_bytes())
        b.write_bytes(a_bytes)
    reopened = PartialStore.open(path)
    assert reopened.context() is None and reopened.verify() == [1, 3]
    ds = simulate_blocks(scene, out, "po", scheduler=inproc, block_size=40, resume=True)
    assert_same_fieldmap(single["po"], ds)
    assert ds.attrs["blocks_repaired"] == 2


def test_a_partial_store_whose_array_type_was_edited_is_refused(scene, inproc, tmp_path):
    """float64 made float32 in one part's metadata: the recomputed blocks would be stored
    rounded (3e-6 off the single-process run, exit 0); the store is refused and kept."""
    out = tmp_path / "field.nc"
    job, description = scene_job(scene, "po", Options(), "cpu", 1, 40)
    path = partial_path(out)
    PartialStore.create(path, job.key, description, job.parts(), job.n_points, 40)
    part = next(p for p in path.iterdir() if (p / "zarr.json").is_file())
    meta = part / "zarr.json"
    meta.write_text(meta.read_text().replace('"float64"', '"float32"'))
    with pytest.raises(ClusterError, match="float32, not the store's") as info:
        simulate_blocks(scene, out, "po", scheduler=inproc, block_size=40, resume=True)
    assert "\n" not in str(info.value) and path.exists()


def _write_bump(path: Path, amplitude_m: float, x0_m: float) -> None:
    """A map CSV (x, y, dz in m) of one Gaussian bump on a 1 m grid covering the 10 m dish."""
    x = np.arange(-6.0, 6.5, 1.0)
    X, Y = np.meshgrid(x, x)
    dz = amplitude_m * np.exp(-((X - x0_m) ** 2 + Y**2) / 4.0)
    rows = "\n".join(f"{a:.17g},{b:.17g},{c:.17g}" for a, b, c in zip(X.ravel(), Y.ravel(), dz.ravel(), strict=True))
    path.write_text("x,y,dz\n" + rows + "\n")


def _map_scene(tmp_path: Path):
    from raysim.scene.scene import load_scene

    text = SMALL.replace('type = "paper"\nscale = 1.0', 'type = "map"\nfile = "bump.csv"')
    (tmp_path / "scene.toml").write_text(text)
    return load_scene(tmp_path / "scene.toml")


def test_a_resume_after_a_file_the_scene_names_changed_is_refused_naming_it(inproc, tmp_path):
    """Blocks 0 and 3 computed with map A, then the map file is edited: the resume would
    merge blocks of the two maps, so it is refused naming the file. With map A back, the
    resume completes to the single-process FieldMap of map A."""
    _write_bump(tmp_path / "bump.csv", 1e-3, 2.0)
    scene = _map_scene(tmp_path)
    expected = simulate(scene, "po")
    out = tmp_path / "field.nc"
    job, description = scene_job(scene, "po", Options(), "cpu", 1, 40)
    store = PartialStore.create(partial_path(out), job.key, description, job.parts(), job.n_points, 40)
    with connect(inproc) as cluster:
        run_blocks(cluster.client, job, [0, 3], block_bounds(job.n_points, 40), store)
    original = (tmp_path / "bump.csv").read_bytes()
    _write_bump(tmp_path / "bump.csv", 1e-3, -2.0)
    with pytest.raises(ClusterError, match=r"differs in: file bump\.csv\)"):
        simulate_blocks(_map_scene(tmp_path), out, "po", scheduler=inproc, block_size=40, resume=True)
    assert sorted(store.markers()) == [0, 3]  # nothing touched
    (tmp_path / "bump.csv").write_bytes(original)
    ds = simulate_blocks(_map_scene(tmp_path), out, "po", scheduler=inproc, block_size=40, resume=True)
    assert_same_fieldmap(expected, ds)
    assert ds.attrs["blocks_reused"] == 2


def test_a_worker_refuses_a_file_the_scene_names_changed_after_the_run_began(inproc, tmp_path):
    """The workers rebuild the scene from its files: one edited after the job was made would
    give blocks of its other version, so the block fails naming the file."""
    _write_bump(tmp_path / "bump.csv", 1e-3, 2.0)
    job, description = scene_job(_map_scene(tmp_path), "po", Options(), "cpu", 1, 40)
    _write_bump(tmp_path / "bump.csv", 2e-3, 2.0)
    store = PartialStore.create(tmp_path / "p.partial.zarr", job.key, description, job.parts(),
                                job.n_points, 40)
    with connect(inproc) as cluster, pytest.raises(ClusterError, match=r"bump\.csv, a file the scene names, changed"):
        run_blocks(cluster.client, job, [1], block_bounds(job.n_points, 40), store)
    assert store.markers() == {}


def test_a_mesh_scene_read_from_its_own_folder_runs_in_blocks(inproc, tmp_path, monkeypatch):
    """``raysim simulate scene.toml --workers 2`` in the scene's folder: its mesh and obstacle
    paths are relative there and absolute on the workers, the same files. It was refused as
    "changed in Python"; the blocks give the single-process FieldMap."""
    import trimesh

    from raysim.scene.scene import load_scene
    from raysim.surface.mesh import paraboloid

    dish = paraboloid(10.0, 4.0, 1.0)
    trimesh.Trimesh(dish.vertices + np.array([0.0, 0.0, 1e-4]) * dish.vertices[:, :1], dish.faces,
                    process=False).export(tmp_path / "dish.ply")
    trimesh.creation.box((0.6, 0.6, 0.1)).apply_translation((0.0, 0.0, 4.0)).export(tmp_path / "cabin.stl")
    text = SMALL.replace('diameter_m = 10.0\nfocal_length_m = 4.0\nresolution_m = 1.0',
                         'mesh = "dish.ply"\nfocal_length_m = 4.0')
    text = text.replace('[[deformation]]\ntype = "paper"\nscale = 1.0\n',
                        '[[obstacle]]\ntype = "mesh"\nfile = "cabin.stl"\n')
    (tmp_path / "scene.toml").write_text(text)
    monkeypatch.chdir(tmp_path)
    scene = load_scene(Path("scene.toml"))
    ds = simulate_blocks(scene, "field.nc", "po", scheduler=inproc, block_size=40)
    assert_same_fieldmap(simulate(scene, "po"), ds)
