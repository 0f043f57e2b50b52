"""A dataset whose scene names a file (a deformation map): a resume after the file changed
is refused naming it, and a project folder moved (or copied) as a whole resumes from the
folder it is in now, never from the old one.

The reference is the store the first, uninterrupted run made: a resumed sample must be that
store's sample again, bit for bit."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import zarr

from raysim.dataset import DatasetError, generate, load_spec

pytestmark = pytest.mark.slow  # stores made by an in-process Dask cluster

SPEC = """
name = "tinymap"
samples = 4
seed = 777
method = "go"
validation_fraction = 0.25
grid_n = 16
dtype = "float32"

[scene]
name = "tiny_dish"
[scene.dish]
diameter_m = 20.0
focal_length_m = 8.0
resolution_m = 2.0
[[scene.deformation]]
type = "map"
file = "bump.csv"
[scene.source]
frequency_hz = 0.3e9
[scene.sphere]
radius_m = 3.0
n_theta = 8
n_phi = 24

[[errors]]
type = "zernike"
n_min = 2
n_max = 4
rms_um = { uniform = [50.0, 200.0] }
"""


def write_bump(path: Path, x0_m: float) -> None:
    """A map CSV (x, y, dz in m): a 0.5 mm Gaussian bump at x = ``x0_m`` on a 1 m grid."""
    x = np.arange(-11.0, 11.5, 1.0)
    X, Y = np.meshgrid(x, x)
    dz = 5e-4 * np.exp(-((X - x0_m) ** 2 + Y**2) / 8.0)
    rows = "\n".join(f"{a:.17g},{b:.17g},{c:.17g}" for a, b, c in zip(X.ravel(), Y.ravel(), dz.ravel(), strict=True))
    path.write_text("x,y,dz\n" + rows + "\n")


def project(folder: Path, x0_m: float = 3.0) -> Path:
    """A project folder: ``spec.toml`` and the ``bump.csv`` its scene names."""
    folder.mkdir(parents=True)
    write_bump(folder / "bump.csv", x0_m)
    (folder / "spec.toml").write_text(SPEC)
    return folder / "spec.toml"


def interrupt(store: Path, samples: list[int]) -> dict[int, np.ndarray]:
    """Make ``samples`` pending as a run killed before them leaves them; their intensities
    as the uninterrupted run made them."""
    group = zarr.open_group(str(store), mode="r+")
    kept = {i: np.asarray(group["intensity"][i]) for i in samples}
    for i in samples:
        group["status"][i] = 0
    return kept


def test_a_resume_after_the_scene_s_map_changed_is_refused_naming_it(tmp_path, inproc):
    spec_path = project(tmp_path / "p")
    store = tmp_path / "p" / "s.zarr"
    generate(load_spec(spec_path), store, scheduler=inproc)
    interrupt(store, [2, 3])
    before = {str(p): p.read_bytes() for p in store.rglob("*") if p.is_file()}
    write_bump(tmp_path / "p" / "bump.csv", -3.0)  # the map is updated between the runs
    with pytest.raises(DatasetError, match=r"bump\.csv, a file its scene names, is not the one"):
        generate(load_spec(spec_path), store, scheduler=inproc, resume=True)
    assert {str(p): p.read_bytes() for p in store.rglob("*") if p.is_file()} == before


def test_a_moved_project_resumes_from_its_new_folder(tmp_path, inproc):
    """The project is copied elsewhere and the old folder's map then edited: the resume of
    the copy must read the copy's map, giving the samples the uninterrupted run made."""
    old = project(tmp_path / "old")
    generate(load_spec(old), tmp_path / "old" / "s.zarr", scheduler=inproc)
    shutil.copytree(tmp_path / "old", tmp_path / "new")
    write_bump(tmp_path / "old" / "bump.csv", -3.0)  # what is left at the old path is another map
    store = tmp_path / "new" / "s.zarr"
    expected = interrupt(store, [1, 3])
    report = generate(load_spec(tmp_path / "new" / "spec.toml"), store, scheduler=inproc, resume=True)
    assert (report.done, report.failed, report.computed) == (4, 0, 2)
    group = zarr.open_group(str(store), mode="r")
    assert Path(group.attrs["spec_base"]) == (tmp_path / "new").resolve()
    for i, values in expected.items():
        assert np.array_equal(np.asarray(group["intensity"][i]), values)
