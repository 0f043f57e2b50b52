"""The package as a user installs it: the wheel and the sdist build, the wheel installs into a
fresh virtual environment outside the repository (its dependencies taken from this
environment, nothing downloaded), and the installed ``raysim`` lists the shipped examples,
simulates one by name and inverts the result."""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import tarfile
import tomllib
import zipfile
from pathlib import Path

import pytest

from raysim.files import example_names

ROOT = Path(__file__).resolve().parent.parent


def _pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_every_package_of_the_tree_is_listed_for_the_wheel():
    listed = set(_pyproject()["tool"]["setuptools"]["packages"])
    on_disk = {".".join(p.parent.relative_to(ROOT).parts)
               for top in ("raysim", "solver", "hardware") for p in (ROOT / top).rglob("__init__.py")}
    assert listed - {"raysim.examples"} == on_disk


def test_the_examples_are_the_scenes_folder_and_resolve_by_name(tmp_path, monkeypatch):
    shipped = sorted(p.stem for p in (ROOT / "scenes").glob("*.toml"))
    assert example_names() == shipped and {"paper_go", "scan_demo", "rig", "dataset_demo"} <= set(shipped)
    from hardware.plan import load_plan
    from raysim.dataset import load_spec
    from raysim.scene import load_scene

    monkeypatch.chdir(tmp_path)
    assert load_scene("paper_go").name == "paper_go"
    plan = load_plan("scan_demo")  # its rig = "rig.toml" resolves beside it
    assert plan.rig.radius == 10.0 and {f.name for f in plan.files} == {"scan_demo.toml", "rig.toml"}
    assert load_spec("dataset_demo").samples > 0
    (tmp_path / "paper_go").write_text("not a scene")  # a path that exists wins
    with pytest.raises(Exception, match="paper_go"):
        load_scene("paper_go")


def _run(args: list[str], cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess:
    done = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"{args}\n{done.stdout}\n{done.stderr}"
    return done


@pytest.mark.slow
def test_the_wheel_installs_outside_the_repository_and_runs(tmp_path):
    dist = tmp_path / "dist"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    _run([sys.executable, "-m", "build", "--no-isolation", "--outdir", str(dist), str(ROOT)], ROOT, env)
    wheel = next(dist.glob("raysim-*.whl"))
    sdist = next(dist.glob("raysim-*.tar.gz"))
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
    assert {f"raysim/examples/{n}.toml" for n in example_names()} <= set(names)
    with tarfile.open(sdist) as archive:
        assert any(n.endswith("/scenes/paper_go.toml") for n in archive.getnames())
    # a fresh environment outside the repository; this one's packages (not raysim) behind it
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], tmp_path, env)
    site = next(venv.glob("lib/python*/site-packages"))
    deps = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (site / "raysim-deps.pth").write_text("".join(f"{p}\n" for p in sorted(deps)))
    python, raysim = venv / "bin" / "python", venv / "bin" / "raysim"
    _run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "--no-index",
          str(wheel)], tmp_path, env)
    work = tmp_path / "work"
    work.mkdir()
    where = _run([str(python), "-c", "import raysim; print(raysim.__file__)"], work, env).stdout
    assert str(ROOT) not in where and str(site) in where
    version = _run([str(raysim), "--version"], work, env).stdout.split()[-1]
    assert version == _pyproject()["project"]["version"]
    listing = _run([str(raysim), "scenes"], work, env).stdout.splitlines()
    assert len(listing) == len(example_names()) and listing[0].split()[0] == example_names()[0]
    _run([str(raysim), "simulate", "paper_go", "-o", "f.nc", "--n-theta", "10", "--n-phi", "20"],
         work, env)
    _run([str(raysim), "invert", "f.nc", "-o", "s.nc", "--refine", "0", "--grid", "64"], work, env)
    check = ("import xarray as xr; a = xr.open_dataset('f.nc').attrs; b = xr.open_dataset('s.nc').attrs;"
             "print(a['raysim_version'], b['raysim_version'], a['scene_name'])")
    assert _run([str(python), "-c", check], work, env).stdout.split() == [version, version, "paper_go"]
    copied = _run([str(raysim), "scenes", "copy", "scan_demo", "mine"], work, env).stdout
    assert (work / "mine" / "scan_demo.toml").is_file() and (work / "mine" / "rig.toml").is_file()
    assert "wrote" in copied


def test_every_output_records_the_version_under_one_name():
    from raysim.dataset.store import versions
    from raysim.version import VERSION_ATTR, __version__
    from tests.test_bad_inputs import _fieldmap

    assert VERSION_ATTR == "raysim_version"
    assert _fieldmap().attrs[VERSION_ATTR] == __version__ == versions()[VERSION_ATTR]
