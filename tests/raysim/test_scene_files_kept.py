"""Commands that read a FieldMap made from a scene also read the files that scene names (its
mesh for the dish, its deformation maps for the truth): an output there is refused, in one line
with exit 2, and the file is left as it was, as ``simulate`` refuses them for a scene.

The FieldMap is written from another folder than the scene's, so its files are found through
the scene's folder the FieldMap records, not the working folder."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

SCENE = """name = "mine"
[dish]
mesh = "my_dish.stl"
[[deformation]]
type = "map"
file = "old_report/surface.nc"
[[deformation]]
type = "map"
file = "bump.png"
[source]
frequency_hz = 1e9
[sphere]
radius_m = 1.0
n_theta = 12
n_phi = 24
"""


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """(folder of the scene and its files, the FieldMap simulated from it, work folder)."""
    import trimesh
    import xarray as xr

    from raysim.maps.fieldmap import save
    from raysim.scene.scene import load_scene
    from raysim.simulate import simulate
    from raysim.surface.mesh import paraboloid

    root = tmp_path_factory.mktemp("scene_files")
    dish = root / "dish"
    (dish / "old_report").mkdir(parents=True)
    mesh = paraboloid(6.0, 3.0, 0.4)
    trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).export(dish / "my_dish.stl")
    x = np.linspace(-3.5, 3.5, 8)
    # an earlier report's SurfaceMap, used as a deformation map: the only file in its folder
    xr.Dataset({"deformation": (("y", "x"), 1e-5 * np.ones((8, 8)), {"units": "m"})},
               coords={"x": ("x", x, {"units": "m"}), "y": ("y", x, {"units": "m"})}
               ).to_netcdf(dish / "old_report" / "surface.nc")
    # a CSV map x,y,dz whose name ends in .png (what render writes)
    rows = [f"{a},{b},{2e-5 * np.exp(-(a * a + b * b))}" for b in x for a in x]
    (dish / "bump.png").write_text("x,y,dz\n" + "\n".join(rows) + "\n")
    (dish / "mine.toml").write_text(SCENE)
    work = root / "work"
    work.mkdir()
    field = work / "field.nc"
    save(simulate(load_scene(dish / "mine.toml"), method="go"), field)
    return dish, field, work


def _refused(result, path: Path, before: str) -> str:
    assert result.code == 2, result.stdout + result.stderr
    line = result.error()
    assert path.is_file() and _digest(path) == before
    return line


def test_invert_refuses_to_write_over_the_mesh_its_fieldmaps_scene_names(made, raysim_cli,
                                                                         monkeypatch):
    dish, field, work = made
    monkeypatch.chdir(work)
    mesh = dish / "my_dish.stl"
    before = _digest(mesh)
    for output in (mesh, Path("..") / "dish" / "my_dish.stl"):
        line = _refused(raysim_cli("invert", str(field), "-o", str(output), "--grid", "32",
                                   "--refine", "0"), mesh, before)
        assert "my_dish.stl" in line and "destroy the input" in line
    # the per-panel table too
    line = _refused(raysim_cli("invert", str(field), "-o", str(work / "s.nc"), "--grid", "32",
                               "--refine", "0", "--panels-csv", str(dish / "bump.png")),
                    dish / "bump.png", _digest(dish / "bump.png"))
    assert "bump.png" in line
    assert not (work / "s.nc").exists()


def test_render_refuses_to_write_over_a_file_its_fieldmaps_scene_names(made, raysim_cli,
                                                                       monkeypatch):
    dish, field, work = made
    monkeypatch.chdir(work)
    target = dish / "bump.png"
    line = _refused(raysim_cli("render", str(field), "-o", str(target), "--kind", "map"),
                    target, _digest(target))
    assert "bump.png" in line and "destroy the input" in line


def test_report_refuses_to_replace_a_folder_holding_a_file_its_fieldmaps_scene_names(
        made, raysim_cli, monkeypatch):
    dish, field, work = made
    monkeypatch.chdir(work)
    folder = dish / "old_report"
    target = folder / "surface.nc"
    line = _refused(raysim_cli("report", str(field), "-o", str(folder), "--no-invert"),
                    target, _digest(target))
    assert "surface.nc" in line
    assert sorted(p.name for p in folder.iterdir()) == ["surface.nc"]


def test_run_invert_from_python_refuses_them_too(made):
    from raysim.errors import RaysimError
    from solver.run import run_invert

    dish, field, _ = made
    mesh = dish / "my_dish.stl"
    before = _digest(mesh)
    with pytest.raises(RaysimError, match="my_dish.stl"):
        run_invert(field, mesh, N=32, refine=0)
    assert _digest(mesh) == before
